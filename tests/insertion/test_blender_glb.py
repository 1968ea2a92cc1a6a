"""The core reads what Blender writes: a car exported from Blender's own glTF exporter (its
defaults, +Y up) comes back in the vehicle frame Blender showed, with the base colour Blender
had. This pins the contract between the add-on's export and the core's mesh reader."""

import numpy as np
import pytest

from symdrive_core.conventions import linear_to_srgb
from symdrive_core.insertion.mesh_to_splats import mesh_to_splats
from symdrive_core.io.mesh import read_mesh

pytestmark = pytest.mark.blender

PAINT = (0.6, 0.05, 0.04)  # Principled BSDF base colour: linear


def _car(bpy):
    """A 4.5 x 1.8 x 1.5 m box, X forward, Z up, moved and turned by its object transform."""
    import bmesh

    mesh = bpy.data.meshes.new("car")
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=1.0)
    bmesh.ops.scale(bm, vec=(4.5, 1.8, 1.5), verts=bm.verts)
    bm.to_mesh(mesh)
    bm.free()
    mat = bpy.data.materials.new("paint")
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*PAINT, 1.0)
    mesh.materials.append(mat)
    ob = bpy.data.objects.new("car", mesh)
    bpy.context.scene.collection.objects.link(ob)
    ob.location = (1.0, -2.0, 0.75)
    ob.rotation_euler = (0.0, 0.0, 0.5)
    bpy.context.view_layer.update()
    return ob


def test_a_glb_from_blenders_exporter_reads_back_in_blenders_frame(tmp_path):
    bpy = pytest.importorskip("bpy")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    ob = _car(bpy)
    world = np.array([ob.matrix_world @ v.co for v in ob.data.vertices])
    path = tmp_path / "car.glb"
    assert bpy.ops.export_scene.gltf(filepath=str(path), export_format="GLB") == {"FINISHED"}
    mesh = read_mesh(path)
    got = np.unique(mesh.verts.round(5), axis=0)
    np.testing.assert_allclose(got, np.unique(world.round(5), axis=0), atol=1e-4)
    g = mesh_to_splats(mesh, 300)
    np.testing.assert_allclose(g.base_colors, np.tile(linear_to_srgb(PAINT), (300, 1)), atol=3e-3)


def test_an_obj_from_blender_written_z_up_reads_back_unchanged(tmp_path):
    bpy = pytest.importorskip("bpy")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    ob = _car(bpy)
    world = np.array([ob.matrix_world @ v.co for v in ob.data.vertices])
    path = tmp_path / "car.obj"
    assert bpy.ops.wm.obj_export(filepath=str(path), forward_axis="Y", up_axis="Z") == {"FINISHED"}
    mesh = read_mesh(path)
    np.testing.assert_allclose(np.unique(mesh.verts.round(4), axis=0), np.unique(world.round(4), axis=0), atol=1e-3)
    g = mesh_to_splats(mesh, 200)
    np.testing.assert_allclose(g.base_colors.mean(0), linear_to_srgb(PAINT), atol=0.02)
