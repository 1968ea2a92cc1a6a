"""The street's parked cars as existing actors (``--parked-existing``).

A parked car never moves: its pose in every frame is its object's ``matrix_world`` (3DRealCar
frame: X forward, Z up, origin at the box centre) and its size ``obj["wlh"]``. Only the cars whose
box projects into at least one drive frame's view become actors (the street builds cars far beyond
the drive). Each gets an object pass index of its own, after the traffic's, so that its visible
pixels can be read from the object-index pass; that changes no rendered colour.
"""

from __future__ import annotations

import numpy as np

from symdrive_core import conventions
from symdrive_core.scene import Pose

GRID = np.linspace(-0.5, 0.5, 5)  # box samples per axis, in units of the box's size


def _box_samples(wlh) -> np.ndarray:
    """Points [125,3] on a grid through the box (corners, faces and inside), local frame."""
    w, l, h = (float(v) for v in wlh)
    g = np.stack(np.meshgrid(GRID, GRID, GRID, indexing="ij"), -1).reshape(-1, 3)
    return g * np.array([l, w, h])


def in_view(pose: Pose, wlh, poses_c2w, K: np.ndarray, width: int, height: int) -> bool:
    """Whether the box projects into at least one of the views ``poses_c2w`` (OpenCV camera-to-world)."""
    pts = pose.apply(_box_samples(wlh))
    for c2w in poses_c2w:
        uv, z = conventions.project_points(pts, conventions.invert_rigid(c2w), K)
        ok = (z > 1e-3) & (uv[:, 0] >= 0) & (uv[:, 0] < width) & (uv[:, 1] >= 0) & (uv[:, 1] < height)
        if ok.any():
            return True
    return False


class Parked:
    """The parked cars in view of the drive: objects, constant poses, sizes and pass indices."""

    def __init__(self, objects, first_index: int, poses_c2w, K: np.ndarray, width: int, height: int):
        self.objects, self.poses, self.sizes = [], [], []
        for obj in objects:
            pose = Pose.from_matrix(np.array(obj.matrix_world, dtype=np.float64))
            wlh = [float(v) for v in obj["wlh"]]
            if in_view(pose, wlh, poses_c2w, K, width, height):
                obj.pass_index = first_index + len(self.objects)
                self.objects.append(obj)
                self.poses.append(pose)
                self.sizes.append(wlh)
        self.first_index = first_index

    def __len__(self) -> int:
        return len(self.objects)

    @staticmethod
    def actor_id(k: int) -> str:
        return f"parked_{k}"

    def pixels(self, index: np.ndarray) -> np.ndarray:
        """Visible pixels of each parked car in an object-index pass."""
        return np.bincount(index.ravel(), minlength=self.first_index + len(self))[
            self.first_index:self.first_index + len(self)]

    def mask(self, index: np.ndarray, k: int) -> np.ndarray:
        return index == self.first_index + k
