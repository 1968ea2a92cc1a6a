"""Any mesh Blender imports reaches the backend: GLB/glTF, PLY, STL and OBJ read into the vehicle
frame with their base colour, scenes flattened with their node transforms."""

import json
from pathlib import Path

import numpy as np
import pytest

from symdrive_core.conventions import linear_to_srgb
from symdrive_core.errors import InputError
from symdrive_core.insertion.assets import load_vehicle_asset
from symdrive_core.insertion.mesh_to_splats import mesh_to_splats, sample_colors
from symdrive_core.io.mesh import read_mesh, read_obj

trimesh = pytest.importorskip("trimesh")

REPO = Path(__file__).resolve().parents[2]
DEMO = REPO / "symdrive_core/data/demo_street/assets"
KENNEY = REPO / "tests/data/meshes/kenney_suv/vehicle-suv.glb"


def _box(extents=(4.0, 2.0, 1.5)):
    return trimesh.creation.box(extents=extents)


def _glb(tmp_path, scene, name="car.glb") -> Path:
    p = tmp_path / name
    p.write_bytes(scene.export(file_type="glb"))
    return p


def _colors_at_vertices(mesh):
    """Sampled colour exactly at each triangle's first corner."""
    tri = np.arange(len(mesh.tris))
    return sample_colors(mesh, mesh.verts[mesh.tris[:, 0]], tri)


def test_glb_nodes_are_flattened_and_turned_from_y_up_to_z_up(tmp_path):
    scene = trimesh.Scene()
    body = _box((1.8, 1.5, 4.5))  # glTF: x width, y up, z length
    wheel = _box((0.3, 0.6, 0.6))
    scene.add_geometry(body, node_name="body", transform=trimesh.transformations.translation_matrix([0, 0.75, 0]))
    spin = trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0])
    scene.add_geometry(wheel, node_name="wheel", transform=trimesh.transformations.translation_matrix([1.0, 0.3, 1.5])
                       @ spin)
    mesh = read_mesh(_glb(tmp_path, scene))
    assert mesh.tris.shape == (24, 3) and len(mesh.materials) == 2
    lo, hi = mesh.verts.min(0), mesh.verts.max(0)
    # (x, y, z)_glTF -> (x, -z, y): width stays on x, length goes to y, up to z; ground at z = 0.
    np.testing.assert_allclose(lo, [-0.9, -2.25, 0.0], atol=1e-6)
    np.testing.assert_allclose(hi, [1.15, 2.25, 1.5], atol=1e-6)
    centres = sorted(mesh.verts[np.unique(mesh.tris[mesh.tri_material == m])].mean(0).round(6).tolist()
                     for m in (0, 1))
    assert centres == [[0.0, 0.0, 0.75], [1.0, -1.5, 0.3]]  # each node's transform applied


def test_glb_base_colour_factor_is_linear_and_shown_through_srgb(tmp_path):
    body = _box()
    body.visual = trimesh.visual.TextureVisuals(
        material=trimesh.visual.material.PBRMaterial(baseColorFactor=[0.6, 0.05, 0.04, 1.0]))
    mesh = read_mesh(_glb(tmp_path, trimesh.Scene(body)))
    g = mesh_to_splats(mesh, 400)
    q = np.round(np.array([0.6, 0.05, 0.04]) * 255) / 255  # glTF stores the factor, trimesh holds 8 bits
    np.testing.assert_allclose(g.base_colors, np.tile(linear_to_srgb(q), (400, 1)), atol=1e-5)


def test_glb_vertex_colours_are_linear(tmp_path):
    body = _box()
    vc = np.tile([255, 64, 0, 255], (len(body.vertices), 1)).astype(np.uint8)
    body.visual = trimesh.visual.ColorVisuals(body, vertex_colors=vc)
    mesh = read_mesh(_glb(tmp_path, trimesh.Scene(body)))
    np.testing.assert_allclose(_colors_at_vertices(mesh), np.tile(linear_to_srgb([1.0, 64 / 255, 0.0]), (12, 1)),
                               atol=1e-3)


def test_glb_texture_is_sampled_at_uv(tmp_path):
    from PIL import Image

    quad = trimesh.Trimesh(vertices=[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], faces=[[0, 1, 2], [0, 2, 3]],
                           process=False)
    tex = np.zeros((8, 8, 3), np.uint8)
    tex[:, :4] = [0, 0, 255]  # left half of the image blue
    tex[:, 4:] = [0, 255, 0]  # right half green
    quad.visual = trimesh.visual.TextureVisuals(
        uv=[[0, 0], [1, 0], [1, 1], [0, 1]],
        material=trimesh.visual.material.PBRMaterial(baseColorTexture=Image.fromarray(tex)))
    mesh = read_mesh(_glb(tmp_path, trimesh.Scene(quad)))
    assert mesh.uvs is not None and mesh.materials[0]["texture"].shape == (8, 8, 3)
    # glTF x stays x, so u runs along x: face centroids left of x = 0.5 are blue, right of it green.
    centroids = mesh.verts[mesh.tris].mean(1)
    c = sample_colors(mesh, centroids, np.arange(len(mesh.tris)))
    left = centroids[:, 0] < 0.5
    assert left.sum() == 1 and np.allclose(c[left], [[0, 0, 1]], atol=0.02)
    assert np.allclose(c[~left], [[0, 1, 0]], atol=0.02)


def test_ply_vertex_colours_are_display_encoded_and_stl_is_grey(tmp_path):
    body = _box()
    body.visual = trimesh.visual.ColorVisuals(body, vertex_colors=np.tile([200, 100, 50, 255], (8, 1)))
    (tmp_path / "car.ply").write_bytes(body.export(file_type="ply"))
    mesh = read_mesh(tmp_path / "car.ply")
    np.testing.assert_allclose(mesh.verts.max(0), [2.0, 1.0, 0.75])  # not turned: PLY is taken as Z up
    np.testing.assert_allclose(_colors_at_vertices(mesh), np.tile([200 / 255, 100 / 255, 50 / 255], (12, 1)),
                               atol=1e-6)
    (tmp_path / "car.stl").write_bytes(_box().export(file_type="stl"))
    np.testing.assert_allclose(mesh_to_splats(read_mesh(tmp_path / "car.stl"), 50).base_colors, 0.5, atol=1e-6)


def test_the_project_obj_assets_sample_exactly_as_before():
    for name in ("hatchback", "sedan", "suv"):
        path = DEMO / name / "mesh.obj"
        old, new = read_obj(path), read_mesh(path)
        a, b = mesh_to_splats(old, 12000, seed=0), mesh_to_splats(new, 12000, seed=0)
        for f in ("means", "quats", "log_scales", "opacity_logits", "sh"):
            assert getattr(a, f).tobytes() == getattr(b, f).tobytes(), (name, f)


def test_a_real_third_party_glb_with_nodes_and_an_external_texture():
    mesh = read_mesh(KENNEY)
    assert len(mesh.materials) == 5 and all(m["texture"] is not None for m in mesh.materials)
    # Kenney's toy SUV: 0.525 m wide, 0.875 m long (glTF z, now y), 0.505 m tall standing on z = 0.
    np.testing.assert_allclose(mesh.verts.max(0) - mesh.verts.min(0), [0.525, 0.875, 0.505], atol=1e-4)
    assert abs(mesh.verts[:, 2].min()) < 1e-6
    g = mesh_to_splats(mesh, 4000)
    colours = np.round(g.base_colors * 8).astype(int)
    distinct, counts = np.unique(colours, axis=0, return_counts=True)
    assert (counts > 40).sum() >= 3  # body paint, tyres, windows: the texture, not one flat grey
    assert not np.allclose(g.base_colors, 0.5, atol=0.02)
    wheels = mesh.tri_material >= 1
    assert np.ptp(mesh.verts[mesh.tris[wheels].ravel(), 1]) > 0.5  # four wheels, front and back


def test_a_glb_under_an_obj_name_is_still_read(tmp_path):
    """The symptom that started this: a GLB handed to the OBJ parser ("cannot parse 'v\\x1f...'")."""
    (tmp_path / "mesh.obj").write_bytes(KENNEY.read_bytes())
    (tmp_path / "Textures").mkdir()
    (tmp_path / "Textures/colormap.png").write_bytes((KENNEY.parent / "Textures/colormap.png").read_bytes())
    assert read_mesh(tmp_path / "mesh.obj").tris.shape == read_mesh(KENNEY).tris.shape


def test_an_obj_the_project_parser_cannot_read_falls_back_to_trimesh(tmp_path):
    text = "v 0 0 0\nv 1 \\\n 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n"  # a line continued
    (tmp_path / "a.obj").write_text(text)
    with pytest.raises(InputError, match="cannot parse"):
        read_obj(tmp_path / "a.obj")
    mesh = read_mesh(tmp_path / "a.obj")
    assert mesh.tris.shape == (2, 3) and np.ptp(mesh.verts, axis=0).tolist() == [1.0, 1.0, 0.0]
    (tmp_path / "b.obj").write_text("v 0 0 0\nv 1 0\nf 1 2 x\n")  # neither reads it: the parser's words
    with pytest.raises(InputError, match="line 2: cannot parse"):
        read_mesh(tmp_path / "b.obj")


@pytest.mark.parametrize("name, data, words", [
    ("car.fbx", b"Kaydara FBX Binary  \x00", "FBX is not read here"),
    ("car.usdz", b"PK\x03\x04", "USD is not read here"),
    ("car.glb", b"glTF\x02\x00\x00\x00garbage", "cannot read GLB"),
    ("car.gltf", b"{not json", "cannot read GLTF"),
    ("car.xyz", b"1 2 3\n", "unsupported mesh format"),
])
def test_unreadable_meshes_say_why(tmp_path, name, data, words):
    (tmp_path / name).write_bytes(data)
    with pytest.raises(InputError, match=words) as exc:
        read_mesh(tmp_path / name)
    assert name in str(exc.value)


def test_points_only_and_missing_files_are_refused(tmp_path):
    cloud = trimesh.PointCloud(np.random.default_rng(0).normal(size=(20, 3)))
    (tmp_path / "cloud.ply").write_bytes(cloud.export(file_type="ply"))
    with pytest.raises(InputError, match="no faces"):
        read_mesh(tmp_path / "cloud.ply")
    with pytest.raises(InputError, match="not found"):
        read_mesh(tmp_path / "nothing.glb")


def test_asset_folder_with_only_a_glb(tmp_path):
    body = _box((1.8, 1.5, 4.5))
    body.visual = trimesh.visual.TextureVisuals(
        material=trimesh.visual.material.PBRMaterial(baseColorFactor=[0.1, 0.2, 0.6, 1.0]))
    _glb(tmp_path, trimesh.Scene(body), "mesh.glb")
    (tmp_path / "wlh.json").write_text(json.dumps({"wlh": [1.8, 4.5, 1.5]}))
    a = load_vehicle_asset(tmp_path, n_samples=300)
    assert a.source.name == "mesh.glb" and len(a.gaussians) == 300
    np.testing.assert_allclose(np.ptp(a.gaussians.means, axis=0), [1.8, 4.5, 1.5], atol=0.05)


def test_an_obj_material_library_outside_its_folder_is_not_read(tmp_path):
    """``mtllib`` in a downloaded OBJ is data: a library beside the file is read, one that climbs
    out of its folder is not (the mesh keeps the default colour)."""
    from symdrive_core.io.mesh import read_obj

    (tmp_path / "pkg").mkdir()
    for where, name in ((tmp_path, "outside.mtl"), (tmp_path / "pkg", "beside.mtl")):
        (where / name).write_text("newmtl red\nKd 1 0 0\n")
    body = "v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\nf 1 2 3\n"
    (tmp_path / "pkg" / "out.obj").write_text("mtllib ../outside.mtl\n" + body)
    (tmp_path / "pkg" / "in.obj").write_text("mtllib beside.mtl\n" + body)
    inside = read_obj(tmp_path / "pkg" / "in.obj")
    outside = read_obj(tmp_path / "pkg" / "out.obj")
    np.testing.assert_allclose(inside.materials[0]["kd"], [1.0, 0.0, 0.0])
    assert not np.allclose(outside.materials[0]["kd"], [1.0, 0.0, 0.0])  # the default colour
