"""Viewport display of splat clouds: a Geometry Nodes "mesh to points" modifier and an unlit material.

The splats live on a vertex-only mesh; this node group turns each vertex into a point whose radius
is the splat's mean scale (times a size factor) and whose colour is the SH DC colour, and hides
nearly transparent splats. No draw handlers or shaders of our own: stable across Blender releases.
"""

from __future__ import annotations

import bpy

from . import compat

GROUP_NAME = "SymDrive Splat Display"
MATERIAL_NAME = "SymDrive Splat"
MODIFIER_NAME = "SymDrive display"
COLOR_ATTRIBUTE = "color"
OPACITY_ATTRIBUTE = "opacity"
SCALE_ATTRIBUTE = "scale"
VERSION = 1  # bump when the node layout changes, so old .blend files get the new group


def splat_material() -> bpy.types.Material:
    mat = bpy.data.materials.get(MATERIAL_NAME)
    if mat is not None:
        return mat
    mat = bpy.data.materials.new(MATERIAL_NAME)
    tree = compat.material_node_tree(mat)
    nodes, links = tree.nodes, tree.links
    nodes.clear()
    attr = nodes.new("ShaderNodeAttribute")
    attr.attribute_type = "GEOMETRY"
    attr.attribute_name = COLOR_ATTRIBUTE
    emit = nodes.new("ShaderNodeEmission")
    out = nodes.new("ShaderNodeOutputMaterial")
    links.new(attr.outputs["Color"], emit.inputs["Color"])
    links.new(emit.outputs["Emission"], out.inputs["Surface"])
    attr.location, emit.location, out.location = (-400, 0), (-150, 0), (100, 0)
    return mat


def _build_group() -> bpy.types.NodeTree:
    ng = bpy.data.node_groups.new(GROUP_NAME, "GeometryNodeTree")
    ng["symdrive_version"] = VERSION
    iface = ng.interface
    iface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    size = iface.new_socket("Size", in_out="INPUT", socket_type="NodeSocketFloat")
    size.default_value, size.min_value = 1.0, 0.0
    min_op = iface.new_socket("Min Opacity", in_out="INPUT", socket_type="NodeSocketFloat")
    min_op.default_value, min_op.min_value, min_op.max_value = 0.05, 0.0, 1.0
    iface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")

    nodes, links = ng.nodes, ng.links
    gin, gout = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    opacity = nodes.new("GeometryNodeInputNamedAttribute")
    opacity.data_type = "FLOAT"
    opacity.inputs["Name"].default_value = OPACITY_ATTRIBUTE
    faint = nodes.new("FunctionNodeCompare")
    faint.data_type, faint.operation = "FLOAT", "LESS_THAN"
    delete = nodes.new("GeometryNodeDeleteGeometry")
    delete.domain = "POINT"
    scale = nodes.new("GeometryNodeInputNamedAttribute")
    scale.data_type = "FLOAT_VECTOR"
    scale.inputs["Name"].default_value = SCALE_ATTRIBUTE
    mean = nodes.new("ShaderNodeVectorMath")
    mean.operation = "DOT_PRODUCT"
    mean.inputs[1].default_value = (1 / 3, 1 / 3, 1 / 3)
    radius = nodes.new("ShaderNodeMath")
    radius.operation = "MULTIPLY"
    to_points = nodes.new("GeometryNodeMeshToPoints")
    to_points.mode = "VERTICES"
    set_mat = nodes.new("GeometryNodeSetMaterial")
    set_mat.inputs["Material"].default_value = splat_material()

    links.new(opacity.outputs["Attribute"], faint.inputs[0])
    links.new(gin.outputs["Min Opacity"], faint.inputs[1])
    links.new(gin.outputs["Geometry"], delete.inputs["Geometry"])
    links.new(faint.outputs["Result"], delete.inputs["Selection"])
    links.new(scale.outputs["Attribute"], mean.inputs[0])
    links.new(mean.outputs["Value"], radius.inputs[0])
    links.new(gin.outputs["Size"], radius.inputs[1])
    links.new(delete.outputs["Geometry"], to_points.inputs["Mesh"])
    links.new(radius.outputs["Value"], to_points.inputs["Radius"])
    links.new(to_points.outputs["Points"], set_mat.inputs["Geometry"])
    links.new(set_mat.outputs["Geometry"], gout.inputs["Geometry"])
    for i, node in enumerate((gin, opacity, faint, delete, scale, mean, radius, to_points, set_mat, gout)):
        node.location = (220 * i, 0)
    return ng


def display_group() -> bpy.types.NodeTree:
    ng = bpy.data.node_groups.get(GROUP_NAME)
    if ng is not None and ng.get("symdrive_version") == VERSION:
        return ng
    if ng is not None:
        ng.name = f"{GROUP_NAME} (old)"
    return _build_group()


def add_display_modifier(obj: bpy.types.Object, size: float = 1.0) -> bpy.types.Modifier:
    mod = obj.modifiers.new(MODIFIER_NAME, "NODES")
    mod.node_group = display_group()
    for item in mod.node_group.interface.items_tree:
        if getattr(item, "in_out", None) == "INPUT" and item.name == "Size":
            compat.set_modifier_input(mod, item.identifier, float(size))
    obj.data.materials.append(splat_material())
    return mod
