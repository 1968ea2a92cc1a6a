"""A background plus one inserted vehicle at its pose, as a frozen view (:mod:`symdrive_core.splat.frozen_view`).

The vehicle is placed in the world (:func:`~.place.place`) and its SH evaluated in its own frame.
"""

from __future__ import annotations

from ..gaussians import Gaussians
from ..scene import Pose
from ..scene.camera import CameraView
from ..splat.frozen_view import FrozenView
from ..splat.tensors import GaussianTensors
from .place import place


def insertion_view(camera: CameraView, background: GaussianTensors | None, vehicle: Gaussians, pose: Pose,
                   *, background_color=(0.0, 0.0, 0.0)) -> FrozenView:
    """``camera``'s view of ``background`` with ``vehicle`` at ``pose``, projected once."""
    return FrozenView(camera, background, place(vehicle, pose), pose.R, background_color=background_color)


def render_insertion(camera: CameraView, background: GaussianTensors | None, vehicle: Gaussians, pose: Pose,
                     *, background_color=(0.0, 0.0, 0.0)):
    """Naive insertion of one vehicle: (rgb [H,W,3], vehicle alpha [H,W]) as numpy."""
    return insertion_view(camera, background, vehicle, pose, background_color=background_color).render_numpy(vehicle)
