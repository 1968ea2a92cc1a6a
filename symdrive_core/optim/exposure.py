"""Each camera's exposure and white balance, learnt with the Gaussians.

The cameras of a rig do not record the same street in the same colours (on KITTI's stereo pair
the right camera is a few per cent brighter than the left), and a camera with automatic exposure
does not record two frames alike. Gaussians fitted to all of them average the differences into
the scene. So each view's render passes through a learnt affine colour transform before the loss
(``rgb' = rgb A^T + b``, 3x4, starting at the identity; drivestudio's fix): per camera, the
first camera that trains being the reference that keeps the identity (the scene is in its
colours), or per view (``frame``), every view pulled towards the identity. Only training renders
pass through it: a lateral or novel view renders in the reference camera's colours, and a
held-out view of another camera is scored through its camera's transform (the frames' mean, per
view).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from ..errors import InputError
from ..io import open_regular
from ..io.atomic import write_text_atomic
from .param_state import SideParameters

EXPOSURE_FILE = "exposure.json"
MODES = ("off", "camera", "frame")
FRAME_PRIOR = 1.0  # weight of |M - [I | 0]|^2 per view in the per-view mode (its gauge)


def _identity() -> torch.Tensor:
    return torch.cat([torch.eye(3), torch.zeros(3, 1)], 1)


class Exposure(SideParameters):
    """The learnt transforms of one fit: by camera name, or by (camera name, frame)."""

    checkpoint_file = "exposure.safetensors"

    def __init__(self, mode: str, reference: str, keys: list, lr: float):
        if mode not in MODES[1:]:
            raise ValueError(f"exposure mode must be one of {', '.join(MODES[1:])}, got {mode!r}")
        self.mode, self.reference = mode, reference
        self.transforms = {k: torch.nn.Parameter(_identity()) for k in keys}
        self.opt = torch.optim.Adam(list(self.transforms.values()), lr=lr) if self.transforms else None

    @staticmethod
    def of(views: list, mode: str, lr: float) -> Exposure | None:
        """The transforms ``views`` need (None: ``mode`` off, or one camera and per camera)."""
        if mode == "off":
            return None
        cameras = list(dict.fromkeys(v.camera_name for v in views))
        if mode == "camera":
            return Exposure(mode, cameras[0], cameras[1:], lr) if len(cameras) > 1 else None
        return Exposure(mode, cameras[0], list(dict.fromkeys((v.camera_name, v.frame) for v in views)), lr)

    def _key(self, view):
        return view.camera_name if self.mode == "camera" else (view.camera_name, view.frame)

    def apply(self, rgb: torch.Tensor, view) -> torch.Tensor:
        """``rgb`` [H, W, 3] as ``view``'s camera records it."""
        m = self.transforms.get(self._key(view))
        return rgb if m is None else rgb @ m[:, :3].T + m[:, 3]

    def penalty(self, n_views: int) -> torch.Tensor | None:
        """The per-view mode's pull towards the identity, per training view (None per camera)."""
        if self.mode != "frame":
            return None
        total = sum(((m - _identity()) ** 2).sum() for m in self.transforms.values())
        return FRAME_PRIOR * total / max(n_views, 1)

    def by_camera(self) -> dict[str, np.ndarray]:
        """Each camera's transform [3, 4] as it stands (per view: the mean of its frames'); the
        reference camera keeps the identity in the per-camera mode."""
        groups: dict[str, list[np.ndarray]] = {}
        for k, m in self.transforms.items():
            groups.setdefault(k if self.mode == "camera" else k[0], []).append(m.detach().double().numpy())
        return {cam: np.mean(ms, axis=0) for cam, ms in groups.items()}

    def params(self) -> dict[str, torch.nn.Parameter]:
        return {k if isinstance(k, str) else f"{k[0]}/{k[1]}": m for k, m in self.transforms.items()}

    def save(self, folder: Path) -> None:
        """``folder/exposure.json``: the mode, the reference camera and each camera's transform."""
        write_text_atomic(Path(folder) / EXPOSURE_FILE, json.dumps({
            "mode": self.mode, "reference": self.reference,
            "cameras": {cam: np.round(m, 6).tolist() for cam, m in self.by_camera().items()}}, indent=1) + "\n")


def read_exposure(folder: Path) -> dict[str, np.ndarray]:
    """Each camera's transform from a reconstruction's ``exposure.json`` (empty without one): the
    file travels with the ``background.ply`` beside it, so a package reconstructed before the run
    is scored in its cameras' colours too. A file that is no such record is an :class:`InputError`
    naming the field."""
    path = Path(folder) / EXPOSURE_FILE
    if not path.is_file():
        return {}
    with open_regular(path) as f:
        text = f.read().decode("utf-8", errors="replace")
    try:
        cameras = json.loads(text)["cameras"]
        out = {str(cam): np.asarray(m, np.float64) for cam, m in cameras.items()}
    except (json.JSONDecodeError, KeyError, TypeError, AttributeError, ValueError):
        raise InputError(path, "expected {\"cameras\": {name: 3x4 numbers}}", "cameras") from None
    for cam, m in out.items():
        if m.shape != (3, 4) or not np.isfinite(m).all():
            raise InputError(path, f"expected 3x4 finite numbers, got shape {m.shape}", f"cameras.{cam}")
    return out


def recorded_colours(image: np.ndarray, transform: np.ndarray | None) -> np.ndarray:
    """A render [H, W, 3] in the colours of the camera with ``transform`` (None: the reference's),
    clipped to [0, 1]: how a held-out view of that camera is scored."""
    if transform is None:
        return image
    return np.clip(image @ transform[:, :3].T + transform[:, 3], 0.0, 1.0).astype(np.float32)
