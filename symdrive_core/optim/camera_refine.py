"""Recorded camera poses refined with the Gaussians (nerfstudio's camera optimiser, gsplat's
``pose_opt``): a drive's poses come from GPS/IMU or odometry, off by centimetres and tenths of a
degree from frame to frame, and a fit at poses that disagree blurs what every view shows.

Each frame's rig gets a learnt rigid correction ``W_f``, the identity at the start: a rotation by
the vector ``w_f`` about the frame's first camera's centre ``c_f``, then a translation ``d_f``::

    W_f(x) = exp([w_f]x) (x - c_f) + c_f + d_f      camera_to_world' = W_f camera_to_world

so every camera of the frame moves with it (a rig is rigid). The fit renders the world moved by
``W_f^-1`` instead of the camera moved by ``W_f`` (the same image), as one more rigid transform of
every layer (:func:`corrected_layers`), so the correction takes the image's gradient through the
Gaussians' positions and orientations as a vehicle's learnt pose does. The view-dependent colours
are evaluated from the uncorrected camera centre, which the correction moves by centimetres.

A frame without a training view (held out) has no image to refine it: it takes the correction
interpolated linearly between the nearest trained frames before and after it (the nearest one
past the ends), so a slowly drifting error is followed there too. A weak pull towards the
identity (``prior_m``, ``prior_rad``) holds the gauge: the whole drive moved together changes no
image. The corrections start after ``start_fraction`` of the iterations, once the Gaussians look
like the street.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from ..conventions import invert_rigid
from ..io.atomic import write_text_atomic
from ..scene import Manifest
from ..splat.compose import Layer
from .config import CameraRefineConfig
from .param_state import SideParameters

CAMERAS_FILE = "cameras.json"  # the refined camera poses, beside the reconstruction's background.ply


def _skew(w: torch.Tensor) -> torch.Tensor:
    z = torch.zeros((), dtype=w.dtype)
    return torch.stack([torch.stack([z, -w[2], w[1]]), torch.stack([w[2], z, -w[0]]),
                        torch.stack([-w[1], w[0], z])])


class CameraRefinement(SideParameters):
    """The per-frame rig corrections of one fit, their prior and their optimiser."""

    checkpoint_file = "cameras.safetensors"

    def __init__(self, centres: dict[int, np.ndarray], n_frames: int, cfg: CameraRefineConfig, start: int):
        """``centres``: each trained frame's first camera centre [3] (world metres)."""
        self.cfg, self.start, self.n_frames = cfg, start, n_frames
        self.frames = sorted(centres)
        self.row = {f: i for i, f in enumerate(self.frames)}
        self.centres = torch.tensor(np.stack([centres[f] for f in self.frames]), dtype=torch.float64)
        self.rotation = torch.nn.Parameter(torch.zeros(len(self.frames), 3, dtype=torch.float64))
        self.translation = torch.nn.Parameter(torch.zeros(len(self.frames), 3, dtype=torch.float64))
        self.opt = torch.optim.Adam([{"params": [self.rotation], "lr": cfg.lr_rad},
                                     {"params": [self.translation], "lr": cfg.lr_m}])

    @staticmethod
    def of(views: list, n_frames: int, cfg: CameraRefineConfig, iters: int) -> CameraRefinement | None:
        """The corrections of the frames ``views`` train (None: refinement off)."""
        if not cfg.enabled:
            return None
        centres: dict[int, np.ndarray] = {}
        for v in views:  # the first camera of each frame is its rig's reference
            if v.frame not in centres:
                w2c = v.viewmat.double().numpy()
                centres[v.frame] = -w2c[:3, :3].T @ w2c[:3, 3]
        return CameraRefinement(centres, n_frames, cfg, round(cfg.start_fraction * iters))

    def params(self) -> dict[str, torch.nn.Parameter]:
        return {"rotation": self.rotation, "translation": self.translation}

    def _vectors(self, frame: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(w, d, c) of ``frame``: its own in the graph where it trained, else interpolated, detached."""
        if frame in self.row:
            r = self.row[frame]
            return self.rotation[r], self.translation[r], self.centres[r]
        after = int(np.searchsorted(self.frames, frame))
        lo, hi = self.row[self.frames[max(after - 1, 0)]], self.row[self.frames[min(after, len(self.frames) - 1)]]
        fl, fh = self.frames[lo], self.frames[hi]
        u = 0.0 if fh == fl else (frame - fl) / (fh - fl)
        with torch.no_grad():
            mix = lambda t: (1.0 - u) * t[lo] + u * t[hi]  # noqa: E731
            return mix(self.rotation), mix(self.translation), mix(self.centres)

    def world_inverse(self, frame: int) -> tuple[torch.Tensor, torch.Tensor]:
        """(R [3, 3], T [3]) float64 of ``W_f^-1``: ``x -> R x + T``."""
        w, d, c = self._vectors(frame)
        R = torch.linalg.matrix_exp(_skew(w)).T
        return R, c - R @ (c + d)

    def penalty(self, n_views: int) -> torch.Tensor:
        """The pull towards the identity, per training view."""
        c = self.cfg
        total = self.rotation.pow(2).sum() / c.prior_rad ** 2 + self.translation.pow(2).sum() / c.prior_m ** 2
        return c.weight * total / max(n_views, 1)

    def camera_to_world(self, frame: int, c2w: np.ndarray) -> np.ndarray:
        """``c2w`` [4, 4] of a camera at ``frame`` moved by that frame's correction."""
        with torch.no_grad():
            R, T = self.world_inverse(frame)
        inverse = np.eye(4)
        inverse[:3, :3], inverse[:3, 3] = R.numpy(), T.numpy()
        return invert_rigid(inverse) @ c2w

    def corrections(self) -> dict:
        """Mean and largest correction (cm, degrees) over the trained frames."""
        d = self.translation.detach().norm(dim=1).numpy() * 100
        w = np.degrees(self.rotation.detach().norm(dim=1).numpy())
        return {"mean_cm": round(float(d.mean()), 2), "max_cm": round(float(d.max()), 2),
                "mean_deg": round(float(w.mean()), 3), "max_deg": round(float(w.max()), 3)}


def corrected_layers(layers: list[Layer], inverse: tuple[torch.Tensor, torch.Tensor]) -> list[Layer]:
    """Every layer moved by ``inverse`` (R, T) after its own placement: the world as the corrected
    camera sees it."""
    R, T = inverse
    out = []
    for layer in layers:
        own_R = None if layer.rotation is None else layer.rotation.to(torch.float64)
        own_T = None if layer.translation is None else layer.translation.to(torch.float64)
        out.append(Layer(layer.gaussians, R if own_R is None else R @ own_R,
                         T if own_T is None else R @ own_T + T, layer.actor_id))
    return out


def write_cameras(out: Path, poses: dict[str, list[np.ndarray]], corrections: dict) -> None:
    """``out/cameras.json``: each camera's refined camera-to-world per frame, and the corrections' sizes."""
    doc = {"corrections": corrections, "cameras": {name: [np.round(p, 9).tolist() for p in frames]
                                                   for name, frames in poses.items()}}
    write_text_atomic(Path(out) / CAMERAS_FILE, json.dumps(doc) + "\n")


def read_cameras(folder: Path) -> dict[str, list[np.ndarray]]:
    """The refined camera poses a reconstruction in ``folder`` wrote (none: an empty dict)."""
    path = Path(folder) / CAMERAS_FILE
    if not path.is_file():
        return {}
    doc = json.loads(path.read_text(encoding="utf-8"))
    return {name: [np.asarray(p, np.float64) for p in frames] for name, frames in doc["cameras"].items()}


def recorded_views(manifest: Manifest, views: list) -> list:
    """``views`` seen from the poses the recording gave (a package an earlier refinement linked
    holds its refined ones): what a refinement starts from."""
    out = []
    for v in views:
        recorded = manifest.camera(v.camera_name).frames[v.frame].recorded_camera_to_world
        out.append(v if recorded is None else
                   replace(v, viewmat=torch.tensor(invert_rigid(recorded), dtype=torch.float32)))
    return out


def refined_poses(manifest: Manifest, cameras: CameraRefinement) -> dict[str, list[np.ndarray]]:
    """Every camera's refined camera-to-world per frame, the cameras left out of training too (a
    rig moves together)."""
    return {cam.name: [cameras.camera_to_world(f, cf.recorded) for f, cf in enumerate(cam.frames)]
            for cam in manifest.cameras}


def with_refined_cameras(manifest: Manifest, poses: dict[str, list[np.ndarray]]) -> Manifest:
    """``manifest`` (changed in place, and returned) with each refined camera's poses the refined
    ones and the recording's kept as ``recorded_camera_to_world``: renders, edits, the add-on and
    the simulator see the street from where its Gaussians were fitted."""
    for cam in manifest.cameras:
        for cf, c2w in zip(cam.frames, poses.get(cam.name, [])):
            if cf.recorded_camera_to_world is None:
                cf.recorded_camera_to_world = cf.camera_to_world
            cf.camera_to_world, cf.world_to_camera = c2w, invert_rigid(c2w)
    return manifest

