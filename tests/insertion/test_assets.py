import json

import numpy as np
import torch

from symdrive_core.conventions import linear_to_srgb
from symdrive_core.gaussians import Gaussians
from symdrive_core.insertion.assets import flip_forward, load_vehicle_asset
from symdrive_core.insertion.mesh_to_splats import mesh_to_splats, sample_colors
from symdrive_core.io.mesh import TriMesh, read_obj
from symdrive_core.io.ply import write_splats
from symdrive_core.rotations import quat_from_yaw, quat_to_matrix
from symdrive_core.scene import Pose
from symdrive_core.scene.place import ground_height, grounded, place
from symdrive_core.splat.sh import eval_sh
from symdrive_core.world.obj import write_obj

from ..conftest import random_gaussians
from . import synthetic


def test_flip_forward_turns_positions_orientations_and_view_dependent_colour():
    g = random_gaussians(40, degree=3, seed=3)
    f = flip_forward(g)
    turn = np.diag([-1.0, -1.0, 1.0])
    np.testing.assert_allclose(f.means, g.means @ turn.T, atol=1e-6)
    np.testing.assert_allclose(quat_to_matrix(f.quats), turn @ quat_to_matrix(g.quats), atol=1e-5)
    d = np.random.default_rng(0).normal(size=(40, 3))
    col_f = eval_sh(3, torch.as_tensor(f.sh, dtype=torch.float64), torch.as_tensor(d @ turn.T))
    col_g = eval_sh(3, torch.as_tensor(g.sh, dtype=torch.float64), torch.as_tensor(d))
    np.testing.assert_allclose(col_f.numpy(), col_g.numpy(), atol=1e-5)
    twice = flip_forward(f)
    np.testing.assert_allclose(twice.means, g.means, atol=1e-6)


def test_place_maps_means_and_rotations():
    g = random_gaussians(20, seed=4)
    pose = Pose(np.array([3.0, -2.0, 0.7]), quat_from_yaw(0.8))
    w = place(g, pose)
    np.testing.assert_allclose(w.means, g.means @ pose.R.T + pose.translation, atol=1e-5)
    np.testing.assert_allclose(quat_to_matrix(w.quats), pose.R @ quat_to_matrix(g.quats), atol=1e-5)
    assert w.log_scales.tobytes() == g.log_scales.tobytes()


def test_ground_height_and_grounding():
    rng = np.random.default_rng(0)
    pts = np.concatenate([rng.uniform(-5, 5, (500, 2)), 0.3 + 0.01 * rng.normal(size=(500, 1))], 1)
    pose = Pose(np.array([0.0, 0.0, 3.0]), quat_from_yaw(0.4))
    gz = ground_height(pts, Pose(np.array([0.0, 0.0, 1.0]), pose.rotation), synthetic.WLH)
    assert abs(gz - 0.3) < 0.03
    assert np.isclose(grounded(pose, synthetic.WLH, gz).translation[2], gz + synthetic.WLH[2] / 2)
    assert ground_height(pts + [100, 0, 0], pose, synthetic.WLH) is None


def test_mesh_samples_lie_on_the_surface_with_material_colours():
    mesh = synthetic.box_mesh()
    g = mesh_to_splats(mesh, 3000, seed=1)
    half = np.array([synthetic.WLH[1], synthetic.WLH[0], synthetic.WLH[2]]) / 2
    on_face = np.isclose(np.abs(g.means), half, atol=1e-5).any(1)
    assert on_face.all() and np.all(np.abs(g.means) <= half + 1e-5)
    top = np.isclose(g.means[:, 2], half[2], atol=1e-5)
    side = np.isclose(np.abs(g.means[:, 1]), half[1], atol=1e-5) & ~top
    np.testing.assert_allclose(g.base_colors[top], np.tile(linear_to_srgb([0.05, 0.05, 0.06]), (top.sum(), 1)),
                               atol=1e-5)
    np.testing.assert_allclose(g.base_colors[side].mean(0), linear_to_srgb([0.6, 0.05, 0.04]), atol=1e-5)
    # Flat along the normal: the smallest scale is a tenth of the others.
    s = np.sort(g.scales, axis=1)
    np.testing.assert_allclose(s[:, 0] / s[:, 1], 0.1, rtol=1e-4)


def test_vertex_colours_and_texture_are_interpolated():
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    vc = np.eye(3)
    mesh = TriMesh(verts, np.array([[0, 1, 2]]), vert_colors=vc)
    pts = np.array([[0.2, 0.3, 0.0]])
    np.testing.assert_allclose(sample_colors(mesh, pts, np.array([0])), [[0.5, 0.2, 0.3]], atol=1e-9)
    tex = np.zeros((4, 4, 3))
    tex[:, 2:] = [0.0, 1.0, 0.0]  # right half green
    tex[:, :2] = [0.0, 0.0, 1.0]  # left half blue
    mesh_t = TriMesh(verts, np.array([[0, 1, 2]]), uvs=verts[:, :2] * 0.98 + 0.01, tri_uvs=np.array([[0, 1, 2]]),
                     tri_material=np.array([0]), materials=[{"name": "t", "kd": np.ones(3), "texture": tex}])
    c = sample_colors(mesh_t, np.array([[0.7, 0.1, 0.0], [0.3, 0.3, 0.0]]), np.array([0, 0]))
    assert c[0, 1] > 0.9 and c[1, 2] > 0.9  # u = 0.7 -> right half, u = 0.3 -> left half


def test_asset_folder_from_splats_or_mesh(tmp_path):
    mesh = synthetic.box_mesh()
    faces = [tuple(t) for t in mesh.tris]
    write_obj(tmp_path / "mesh.obj", mesh.verts, faces, list(mesh.tri_material),
              [(m["name"], tuple(m["kd"])) for m in mesh.materials])
    (tmp_path / "wlh.json").write_text(json.dumps({"wlh": list(synthetic.WLH)}))
    from_mesh = load_vehicle_asset(tmp_path, n_samples=500)
    assert len(from_mesh.gaussians) == 500 and from_mesh.source.name == "mesh.obj"
    assert read_obj(tmp_path / "mesh.obj").tris.shape == (12, 3)
    write_splats(tmp_path / "splats.ply", Gaussians.from_activated(
        np.zeros((3, 3)), np.tile([1.0, 0, 0, 0], (3, 1)), np.full((3, 3), 0.1), np.full(3, 0.5), np.full((3, 3), 0.5)))
    a = load_vehicle_asset(tmp_path, flip=True)
    assert len(a.gaussians) == 3 and a.source.name == "splats.ply"
    np.testing.assert_allclose(a.wlh, synthetic.WLH)
