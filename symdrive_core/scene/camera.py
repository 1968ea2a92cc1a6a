"""One pinhole camera as every stage sees it: OpenCV axes (x right, y down, z forward), ``K`` with
pixel centres at +0.5, the world-to-camera matrix and the image size. Shifting it sideways (the
lateral views) and cropping it (harmonization and fine-tuning windows) give cameras of the same
type, so renderers take one kind of view."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import conventions


@dataclass(frozen=True)
class CameraView:
    world_to_camera: np.ndarray  # [4, 4] OpenCV
    K: np.ndarray  # [3, 3]
    width: int
    height: int

    @classmethod
    def of_frame(cls, camera, frame: int) -> CameraView:
        """The view of a package camera (``scene.Camera``) at recorded frame ``frame``."""
        cf = camera.frames[frame]
        return cls(cf.world_to_camera, cf.K, camera.width, camera.height)

    @property
    def camera_to_world(self) -> np.ndarray:
        return conventions.invert_rigid(self.world_to_camera)

    def shifted(self, offset_m: float) -> CameraView:
        """The same camera moved ``offset_m`` metres along its own +x (right)."""
        c2w = conventions.lateral_shift(self.camera_to_world, offset_m)
        return CameraView(conventions.invert_rigid(c2w), self.K, self.width, self.height)

    def crop(self, rows: slice, cols: slice) -> CameraView:
        """The sub-window ``[rows, cols]`` as a camera of its own (principal point moved)."""
        K = np.array(self.K, dtype=np.float64, copy=True)
        K[0, 2] -= cols.start
        K[1, 2] -= rows.start
        return CameraView(self.world_to_camera, K, cols.stop - cols.start, rows.stop - rows.start)


class SeenBy:
    """For records of an image and the camera it was taken with (``camera: CameraView``): the
    camera's fields read through, so such a record is passed wherever a view's K, pose and size
    are read."""

    camera: CameraView

    @property
    def K(self) -> np.ndarray:
        return self.camera.K

    @property
    def world_to_camera(self) -> np.ndarray:
        return self.camera.world_to_camera

    @property
    def camera_to_world(self) -> np.ndarray:
        return self.camera.camera_to_world

    @property
    def width(self) -> int:
        return self.camera.width

    @property
    def height(self) -> int:
        return self.camera.height
