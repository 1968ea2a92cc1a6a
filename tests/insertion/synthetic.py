"""A small synthetic street for insertion tests: a textured ground plane and a box car."""

from __future__ import annotations

import numpy as np

from symdrive_core import conventions
from symdrive_core.gaussians import Gaussians
from symdrive_core.insertion.mesh_to_splats import mesh_to_splats
from symdrive_core.io.mesh import TriMesh
from symdrive_core.rotations import quat_from_yaw
from symdrive_core.scene import Pose
from symdrive_core.scene.camera import CameraView

from ..conftest import look_at_c2w

WLH = (1.8, 4.0, 1.4)


def box_mesh(wlh=WLH, kd=((0.6, 0.05, 0.04), (0.05, 0.05, 0.06))) -> TriMesh:
    """A closed box in the 3DRealCar frame: sides in material 0, top and bottom in material 1."""
    c = conventions.vehicle_box_corners(wlh)  # index = 4 ix + 2 iy + iz
    quads = [(0, 4, 6, 2), (1, 3, 7, 5), (0, 1, 5, 4), (2, 6, 7, 3), (0, 2, 3, 1), (4, 5, 7, 6)]
    mats = [1, 1, 0, 0, 0, 0]  # bottom, top, right, left, back, front
    tris, tri_mat = [], []
    for q, m in zip(quads, mats):
        tris += [(q[0], q[1], q[2]), (q[0], q[2], q[3])]
        tri_mat += [m, m]
    materials = [{"name": f"m{i}", "kd": np.asarray(k, dtype=np.float64), "texture": None} for i, k in enumerate(kd)]
    return TriMesh(c, np.asarray(tris), tri_material=np.asarray(tri_mat), materials=materials)


def car(n=1500, seed=0) -> Gaussians:
    return mesh_to_splats(box_mesh(), n, seed=seed)


def ground(extent=14.0, step=0.25, seed=1) -> Gaussians:
    """Flat Gaussians tiling z = 0 around (8, 0) with a grey, slightly mottled colour."""
    xs = np.arange(8 - extent, 8 + extent, step)
    ys = np.arange(-extent, extent, step)
    X, Y = np.meshgrid(xs, ys)
    n = X.size
    rng = np.random.default_rng(seed)
    means = np.stack([X.ravel(), Y.ravel(), np.zeros(n)], 1)
    grey = 0.45 + 0.1 * np.sin(X.ravel() * 1.3) * np.cos(Y.ravel() * 0.7) + 0.03 * rng.normal(size=n)
    colors = np.clip(np.stack([grey, grey, 1.05 * grey], 1), 0, 1)
    scales = np.tile([step, step, 0.02], (n, 1))
    return Gaussians.from_activated(means, np.tile([1.0, 0, 0, 0], (n, 1)), scales, np.full(n, 0.98), colors)


def car_pose(x=8.0, y=0.0, yaw=0.3) -> Pose:
    return Pose(np.array([x, y, WLH[2] / 2]), quat_from_yaw(yaw))


def camera(eye=(0.0, 0.0, 1.6), target=(8.0, 0.0, 0.5), width=64, height=40, fov_deg=60.0) -> CameraView:
    c2w = look_at_c2w(eye, target)
    K = conventions.intrinsics_from_fov(width, height, np.deg2rad(fov_deg))
    return CameraView(conventions.invert_rigid(c2w), K, width, height)
