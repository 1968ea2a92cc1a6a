"""A set of 3D Gaussians as stored at rest (unactivated), with activated views.

numpy only (the Blender add-on imports it); torch tensors are made in ``symdrive_core.splat``.
Storage follows the INRIA 3DGS PLY: opacity logits, log scales, raw (unnormalised) quaternions
``(w, x, y, z)`` and spherical-harmonic coefficients ``sh[N, K, 3]`` with ``K = (degree + 1)**2``
(``sh[:, 0]`` is ``f_dc``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# the real SH basis constants of 3DGS, per degree (the numba kernels and the float64 oracle keep
# inline copies: kernels read plain scalars, and the oracle checks everything else independently)
SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
         0.5462742152960396)
SH_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
         -0.4570457994644658, 1.445305721320277, -0.5900435899266435)


def sh_coeff_count(degree: int) -> int:
    return (int(degree) + 1) ** 2


def sh_degree_from_count(k: int) -> int:
    degree = int(round(np.sqrt(k))) - 1
    if degree < 0 or (degree + 1) ** 2 != k:
        raise ValueError(f"{k} SH coefficients per channel is not (degree+1)^2 for any degree")
    return degree


def rgb_to_sh_dc(rgb: np.ndarray) -> np.ndarray:
    """Colour in [0, 1] -> degree-0 SH coefficient (inverse of ``SH_C0 * c + 0.5``)."""
    return (np.asarray(rgb, dtype=np.float32) - 0.5) / SH_C0


def sh_dc_to_rgb(dc: np.ndarray) -> np.ndarray:
    return np.clip(SH_C0 * np.asarray(dc, dtype=np.float32) + 0.5, 0.0, None)


def sigmoid(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    return (0.5 * (1.0 + np.tanh(0.5 * x))).astype(np.float32)


def logit(p: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    p = np.clip(np.asarray(p, dtype=np.float64), eps, 1.0 - eps)
    return np.log(p / (1.0 - p)).astype(np.float32)


@dataclass
class Gaussians:
    means: np.ndarray  # [N, 3] float32, metres
    quats: np.ndarray  # [N, 4] float32, raw wxyz
    log_scales: np.ndarray  # [N, 3] float32
    opacity_logits: np.ndarray  # [N] float32
    sh: np.ndarray  # [N, K, 3] float32
    normals: np.ndarray | None = None  # [N, 3] when the file had them
    extra: dict[str, np.ndarray] = field(default_factory=dict)  # unknown per-vertex properties

    def __post_init__(self) -> None:
        n = self.means.shape[0]
        shapes = {
            "means": (self.means, (n, 3)),
            "quats": (self.quats, (n, 4)),
            "log_scales": (self.log_scales, (n, 3)),
            "opacity_logits": (self.opacity_logits, (n,)),
        }
        for name, (arr, shape) in shapes.items():
            if arr.shape != shape:
                raise ValueError(f"Gaussians.{name}: expected shape {shape}, got {arr.shape}")
        if self.sh.ndim != 3 or self.sh.shape[0] != n or self.sh.shape[2] != 3:
            raise ValueError(f"Gaussians.sh: expected shape ({n}, K, 3), got {self.sh.shape}")
        sh_degree_from_count(self.sh.shape[1])

    def __len__(self) -> int:
        return int(self.means.shape[0])

    @property
    def sh_degree(self) -> int:
        return sh_degree_from_count(self.sh.shape[1])

    @property
    def scales(self) -> np.ndarray:
        return np.exp(self.log_scales.astype(np.float64)).astype(np.float32)

    @property
    def opacities(self) -> np.ndarray:
        return sigmoid(self.opacity_logits)

    @property
    def unit_quats(self) -> np.ndarray:
        """Normalised quaternions; a zero quaternion becomes the identity rather than NaN."""
        q = self.quats.astype(np.float64)
        norm = np.linalg.norm(q, axis=1, keepdims=True)
        out = np.where(norm > 0, q / np.where(norm > 0, norm, 1.0), np.array([1.0, 0, 0, 0]))
        return out.astype(np.float32)

    @property
    def base_colors(self) -> np.ndarray:
        """View-independent colour from the DC term, [N, 3] in [0, inf)."""
        return sh_dc_to_rgb(self.sh[:, 0, :])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        if len(self) == 0:
            return np.zeros(3, np.float32), np.zeros(3, np.float32)
        return self.means.min(axis=0), self.means.max(axis=0)

    def subset(self, index) -> Gaussians:
        return Gaussians(
            means=self.means[index],
            quats=self.quats[index],
            log_scales=self.log_scales[index],
            opacity_logits=self.opacity_logits[index],
            sh=self.sh[index],
            normals=None if self.normals is None else self.normals[index],
            extra={k: v[index] for k, v in self.extra.items()},
        )

    def finite_mask(self) -> np.ndarray:
        """True for Gaussians whose every parameter is finite."""
        ok = np.isfinite(self.means).all(1) & np.isfinite(self.quats).all(1)
        ok &= np.isfinite(self.log_scales).all(1) & np.isfinite(self.opacity_logits)
        ok &= np.isfinite(self.sh).all(axis=(1, 2))
        return ok

    @staticmethod
    def from_activated(means, quats, scales, opacities, colors_or_sh) -> Gaussians:
        """Build from activated values; ``colors_or_sh`` is RGB [N,3] or SH [N,K,3]."""
        c = np.asarray(colors_or_sh, dtype=np.float32)
        sh = rgb_to_sh_dc(c)[:, None, :] if c.ndim == 2 else c
        return Gaussians(
            means=np.asarray(means, dtype=np.float32),
            quats=np.asarray(quats, dtype=np.float32),
            log_scales=np.log(np.asarray(scales, dtype=np.float64)).astype(np.float32),
            opacity_logits=logit(opacities),
            sh=sh.astype(np.float32),
        )
