"""Procedural Cycles materials: asphalt, concrete, facades with windows, paint, glass, foliage.

Textures are node-based (noise, brick, Voronoi) in object or world coordinates, so no image
files and no UVs are needed and every material is reproducible from its parameters alone.
Each material records its mean albedo in ``mat["albedo"]``: the vehicle splat assets are
coloured from it (studio-lit colours, as a 3DRealCar capture would be).
"""

from __future__ import annotations

import bpy

from . import compat


def _principled(name: str, color, roughness=0.6, metallic=0.0, specular=0.5):
    mat = bpy.data.materials.new(name)
    tree = compat.node_tree(mat)
    bsdf = tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Metallic"].default_value = metallic
    bsdf.inputs["Specular IOR Level"].default_value = specular
    mat["albedo"] = list(color)
    return mat, tree, bsdf


def _link(tree, a, b):
    tree.links.new(a, b)


def _coords(tree, world: bool = False):
    tc = tree.nodes.new("ShaderNodeTexCoord")
    if world:
        geo = tree.nodes.new("ShaderNodeNewGeometry")
        return geo.outputs["Position"]
    return tc.outputs["Object"]


def _ramp(tree, fac, c0, c1):
    ramp = tree.nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].color = (*c0, 1.0)
    ramp.color_ramp.elements[1].color = (*c1, 1.0)
    _link(tree, fac, ramp.inputs["Fac"])
    return ramp.outputs["Color"]


def _noise(tree, vector, scale, detail=4.0):
    n = tree.nodes.new("ShaderNodeTexNoise")
    n.inputs["Scale"].default_value = scale
    n.inputs["Detail"].default_value = detail
    _link(tree, vector, n.inputs["Vector"])
    return n.outputs["Fac"]


def _bump(tree, bsdf, height, strength):
    b = tree.nodes.new("ShaderNodeBump")
    b.inputs["Strength"].default_value = strength
    _link(tree, height, b.inputs["Height"])
    _link(tree, b.outputs["Normal"], bsdf.inputs["Normal"])


def plain(name, color, roughness=0.6, metallic=0.0):
    return _principled(name, color, roughness, metallic)[0]


def mottled(name, c0, c1, scale=3.0, roughness=0.8, bump=0.15, world=True):
    """Two-colour noise blend (asphalt, concrete, foliage, bark); world coordinates by default."""
    mat, tree, bsdf = _principled(name, [(a + b) / 2 for a, b in zip(c0, c1)], roughness)
    fac = _noise(tree, _coords(tree, world), scale)
    _link(tree, _ramp(tree, fac, c0, c1), bsdf.inputs["Base Color"])
    if bump:
        _bump(tree, bsdf, _noise(tree, _coords(tree, world), scale * 8.0), bump)
    return mat


def tiles(name, tile_color, joint_color, size=0.5, roughness=0.8):
    """Paving slabs: a brick pattern in world XY with dark joints."""
    mat, tree, bsdf = _principled(name, tile_color, roughness)
    brick = tree.nodes.new("ShaderNodeTexBrick")
    brick.inputs["Scale"].default_value = 1.0 / size
    brick.inputs["Mortar Size"].default_value = 0.03
    brick.inputs["Color1"].default_value = (*tile_color, 1.0)
    brick.inputs["Color2"].default_value = (*[c * 0.92 for c in tile_color], 1.0)
    brick.inputs["Mortar"].default_value = (*joint_color, 1.0)
    _link(tree, _coords(tree, True), brick.inputs["Vector"])
    _link(tree, brick.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


def facade(name, wall, wall2, window, storey=3.2, bay=2.6, window_frac=0.45, brick=False):
    """Building wall with a grid of windows, in object coordinates (u = x + y, v = z).

    A Brick texture whose "bricks" are the windows and whose "mortar" is the wall gives a
    window grid; the wall itself is plaster noise or small bricks.
    """
    mat, tree, bsdf = _principled(name, wall, 0.85)
    coords = _coords(tree)
    sep = tree.nodes.new("ShaderNodeSeparateXYZ")
    _link(tree, coords, sep.inputs["Vector"])
    add = tree.nodes.new("ShaderNodeMath")
    _link(tree, sep.outputs["X"], add.inputs[0])
    _link(tree, sep.outputs["Y"], add.inputs[1])
    uv = tree.nodes.new("ShaderNodeCombineXYZ")
    _link(tree, add.outputs["Value"], uv.inputs["X"])
    _link(tree, sep.outputs["Z"], uv.inputs["Y"])

    if brick:
        wall_tex = tree.nodes.new("ShaderNodeTexBrick")
        wall_tex.inputs["Scale"].default_value = 4.0
        wall_tex.inputs["Mortar Size"].default_value = 0.015
        wall_tex.inputs["Color1"].default_value = (*wall, 1.0)
        wall_tex.inputs["Color2"].default_value = (*wall2, 1.0)
        wall_tex.inputs["Mortar"].default_value = (0.55, 0.53, 0.5, 1.0)
        _link(tree, uv.outputs["Vector"], wall_tex.inputs["Vector"])
        wall_color = wall_tex.outputs["Color"]
    else:
        wall_color = _ramp(tree, _noise(tree, coords, 1.5), wall, wall2)

    grid = tree.nodes.new("ShaderNodeTexBrick")
    grid.offset = 0.0
    grid.squash_frequency = 1
    grid.inputs["Scale"].default_value = 1.0
    grid.inputs["Brick Width"].default_value = bay
    grid.inputs["Row Height"].default_value = storey
    grid.inputs["Mortar Size"].default_value = (1.0 - window_frac) * storey * 0.5
    grid.inputs["Mortar Smooth"].default_value = 0.0
    _link(tree, uv.outputs["Vector"], grid.inputs["Vector"])
    mix = tree.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    _link(tree, grid.outputs["Fac"], mix.inputs["Factor"])  # 1 on the mortar (the wall)
    mix.inputs["A"].default_value = (*window, 1.0)
    _link(tree, wall_color, mix.inputs["B"])
    _link(tree, mix.outputs["Result"], bsdf.inputs["Base Color"])
    rough = tree.nodes.new("ShaderNodeMapRange")
    _link(tree, grid.outputs["Fac"], rough.inputs["Value"])
    rough.inputs["To Min"].default_value = 0.15
    rough.inputs["To Max"].default_value = 0.85
    _link(tree, rough.outputs["Result"], bsdf.inputs["Roughness"])
    return mat


def sky_world(overcast: bool, sun_elevation: float, sun_rotation: float, strength: float):
    """World background: a Nishita sky (sun disc off: the sun lamp lights the scene) or a flat
    overcast grey."""
    world = bpy.data.worlds.new("sky")
    tree = compat.node_tree(world)
    bg = tree.nodes["Background"]
    if overcast:
        bg.inputs["Color"].default_value = (0.78, 0.8, 0.83, 1.0)
        bg.inputs["Strength"].default_value = strength
    else:
        sky = tree.nodes.new("ShaderNodeTexSky")
        compat.set_single_scattering_sky(sky, dust_density=1.5)
        sky.sun_disc = False
        sky.sun_elevation = sun_elevation
        sky.sun_rotation = sun_rotation
        sky.air_density = 1.0
        _link(tree, sky.outputs["Color"], bg.inputs["Color"])
        bg.inputs["Strength"].default_value = strength
    return world
