"""What a real camera adds to Cycles' clean image: an exposure that changes from image to image,
blur, and sensor noise.

A restorer trained on clean renders of one street has never seen them, and every recorded drive
has them; a family of generated streets with them is nearer the drives it will restore. Every image
the generator's camera records goes through the same model (recorded frames, lateral truth,
insertion and edit truth): the images of one frame share its exposure, each draws its own noise,
seeded by the generator seed, the frame and the image's path in the package, so a package
regenerates bit for bit. Off by default: the built-in street is clean.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SensorEffects:
    noise: float = 0.0  # standard deviation of additive Gaussian noise, in sRGB units of [0, 1]
    blur_px: float = 0.0  # standard deviation of a Gaussian blur, in pixels
    exposure_jitter: float = 0.0  # each frame's gain is exp(u), u uniform in [-j, j]

    @property
    def active(self) -> bool:
        return bool(self.noise or self.blur_px or self.exposure_jitter)

    def apply(self, rgb: np.ndarray, seed: int, frame: int, key: str) -> np.ndarray:
        """``rgb`` [H, W, 3] in [0, 1] as this camera records it at ``frame``: every image of one
        frame shares its exposure (one moment, one auto-exposure), ``key`` (the image's package
        path) draws its own noise."""
        if not self.active:
            return rgb
        out = np.asarray(rgb, dtype=np.float32)
        if self.exposure_jitter:
            u = np.random.default_rng([seed, frame]).uniform(-self.exposure_jitter, self.exposure_jitter)
            out = out * np.float32(np.exp(u))
        if self.blur_px:
            out = gaussian_blur(out, self.blur_px)
        if self.noise:
            rng = np.random.default_rng([seed, frame, zlib.crc32(key.encode())])
            out = out + rng.normal(0.0, self.noise, out.shape).astype(np.float32)
        return np.clip(out, 0.0, 1.0)

    def to_json(self) -> dict:
        return {"noise": self.noise, "blur_px": self.blur_px, "exposure_jitter": self.exposure_jitter}


def gaussian_blur(rgb: np.ndarray, sigma_px: float) -> np.ndarray:
    """``rgb`` convolved by OpenImageIO with a sampled Gaussian of ``sigma_px`` (radius 3 sigma,
    edges clamped)."""
    import OpenImageIO as oiio

    r = int(np.ceil(3.0 * sigma_px))
    x = np.arange(-r, r + 1)
    g = np.exp(-0.5 * (x / sigma_px) ** 2)
    g /= g.sum()
    kernel = oiio.ImageBuf(np.outer(g, g).astype(np.float32)[:, :, None])
    kernel.set_origin(-r, -r)  # centred on the pixel it writes
    out = oiio.ImageBufAlgo.convolve(oiio.ImageBuf(np.ascontiguousarray(rgb, dtype=np.float32)), kernel)
    return out.get_pixels(oiio.FLOAT).reshape(rgb.shape)
