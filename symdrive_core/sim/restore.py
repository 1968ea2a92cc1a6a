"""Online restoration of the views off the recorded path (``SimConfig(restore=True)``).

When the ego is more than ``restore_threshold_m`` sideways of the recorded path, each camera's
background view goes through the project's restorer (:mod:`symdrive_core.diffusion.restore`),
auto-regressively from the nearest recorded frame: a :class:`~symdrive_core.diffusion.restore.
LateralChain` per (camera, frame), started from that frame's recorded image (resized to the
observation's size), walks outward in ``restore_ar_step_m`` steps. Results are cached per (frame,
camera, offset rounded to ``restore_offset_round_m``), so revisiting a place costs nothing.

The approximation: the restorer's camera model is a recorded camera moved along its own right
axis (:func:`symdrive_core.conventions.lateral_shift`), same orientation, same place along the
path. The ego's camera is generally not such a pose (its heading differs from the recorded one,
and it sits between recorded frames), so the restored background is the view at the nearest
recorded frame (nearest camera centre) shifted by the ego camera's lateral offset from it
(measured along that frame's right axis, rounded), not at the ego camera's exact pose. The
current traffic is then rendered at the ego camera's exact pose and composited over it (the
restored background keeps whatever the recorded image showed).

The diffusion model (:func:`symdrive_core.diffusion.models.load_restorer`) and the background
splats for its renders are loaded at the first off-path view, never with ``restore=False``.
"""

from __future__ import annotations

import numpy as np

from .. import conventions


class OnlineRestorer:
    def __init__(self, env):
        self.env, self.config = env, env.config
        self.model = None
        self._render = None
        self.chains: dict = {}  # (camera, frame) -> LateralChain
        self.cache: dict = {}  # (frame, camera, rounded offset) -> float [H, W, 3] background
        self.samples = 0

    def _load(self) -> None:
        from ..diffusion.models import load_restorer
        from ..io.ply import read_splats
        from ..splat.render import SplatRenderer

        m = self.env.manifest
        if not m.background_splats:
            raise ValueError("restore=True needs the package's background splats")
        self.model = load_restorer()
        self._render = SplatRenderer(read_splats(m.resolve(m.background_splats)))

    def place(self, camera: str, c2w: np.ndarray) -> tuple[int, float]:
        """(nearest recorded frame by camera centre, lateral offset m along its right axis, rounded)."""
        cam = self.env.manifest.camera(camera)
        centres = np.array([cf.camera_to_world[:3, 3] for cf in cam.frames])
        fi = int(np.argmin(np.linalg.norm(centres - c2w[:3, 3], axis=1)))
        rec = cam.frames[fi].camera_to_world
        off = float((c2w[:3, 3] - rec[:3, 3]) @ rec[:3, 0])
        q = self.config.restore_offset_round_m
        return fi, (round(off / q) * q if q > 0 else off)

    def _chain(self, camera: str, fi: int):
        from ..diffusion.restore import LateralChain
        from ..scene.camera import CameraView

        key = (camera, fi)
        if key not in self.chains:
            if self.model is None:
                self._load()
            m, env = self.env.manifest, self.env
            cam = m.camera(camera)
            cf = cam.frames[fi]
            w, h = env.image_size(cam)
            K = conventions.scale_intrinsics(cf.K, w / cam.width, h / cam.height)
            view = CameraView(cf.world_to_camera, K, w, h)
            if cf.image:
                from ..io.images import read_image

                recorded = _resize(read_image(m.resolve(cf.image), channels=3), w, h)
            else:
                recorded = self._render(view)
            self.chains[key] = LateralChain(self.model, self._render, recorded, view, self.config.restore_sampler)
        return self.chains[key]

    def background(self, camera: str, c2w: np.ndarray) -> np.ndarray | None:
        """The restored background (float [H, W, 3] in [0, 1]) for the ego camera at ``c2w``;
        None when its rounded offset from the nearest recorded frame is zero."""
        fi, off = self.place(camera, c2w)
        if off == 0:
            return None
        key = (fi, camera, round(off, 6))
        if key not in self.cache:
            chain = self._chain(camera, fi)
            before = chain.samples
            self.cache[key] = np.asarray(chain.restore(off, self.config.restore_ar_step_m), dtype=np.float32)
            self.samples += chain.samples - before
        return self.cache[key]


def _resize(image: np.ndarray, w: int, h: int) -> np.ndarray:
    """float [H, W, 3] in [0, 1] at (w, h) (area-averaged when shrinking)."""
    image = np.asarray(image, dtype=np.float32)
    if image.shape[:2] == (h, w):
        return image
    import torch
    import torch.nn.functional as F

    t = torch.as_tensor(np.ascontiguousarray(image)).permute(2, 0, 1)[None]
    mode = "area" if w <= image.shape[1] and h <= image.shape[0] else "bilinear"
    out = F.interpolate(t, size=(h, w), mode=mode, **({} if mode == "area" else {"align_corners": False}))
    return out[0].permute(1, 2, 0).clamp(0, 1).numpy()
