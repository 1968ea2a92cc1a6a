"""Real spherical harmonics up to degree 3 (the 3DGS basis and constants), in torch.

``eval_sh`` returns the raw SH value per channel; the colour the rasterizer uses is
``max(eval_sh + 0.5, 0)`` (:func:`sh_to_color`). Directions are normalised inside (a zero direction
gives a zero vector, never NaN). Coefficients are ``sh[N, K, 3]`` with ``K >= (degree + 1)**2``.
"""

from __future__ import annotations

import torch

SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
         0.5462742152960396)
SH_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
         -0.4570457994644658, 1.445305721320277, -0.5900435899266435)


def sh_basis(degree: int, dirs: torch.Tensor) -> torch.Tensor:
    """Basis values [N, (degree+1)^2] at unit directions ``dirs`` [N, 3]."""
    if not 0 <= degree <= 3:
        raise ValueError(f"SH degree must be 0..3, got {degree}")
    n = dirs.shape[0]
    cols = [torch.full((n,), SH_C0, dtype=dirs.dtype, device=dirs.device)]
    if degree >= 1:
        x, y, z = dirs.unbind(-1)
        cols += [-SH_C1 * y, SH_C1 * z, -SH_C1 * x]
        if degree >= 2:
            xx, yy, zz = x * x, y * y, z * z
            xy, yz, xz = x * y, y * z, x * z
            cols += [SH_C2[0] * xy, SH_C2[1] * yz, SH_C2[2] * (2.0 * zz - xx - yy), SH_C2[3] * xz,
                     SH_C2[4] * (xx - yy)]
            if degree >= 3:
                cols += [SH_C3[0] * y * (3.0 * xx - yy), SH_C3[1] * xy * z, SH_C3[2] * y * (4.0 * zz - xx - yy),
                         SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy), SH_C3[4] * x * (4.0 * zz - xx - yy),
                         SH_C3[5] * z * (xx - yy), SH_C3[6] * x * (xx - 3.0 * yy)]
    return torch.stack(cols, dim=-1)


def normalize_dirs(dirs: torch.Tensor) -> torch.Tensor:
    """Unit vectors; a zero (or non-finite) direction becomes zero with a finite gradient."""
    ok = torch.isfinite(dirs).all(-1, keepdim=True)
    d = torch.where(ok, dirs, torch.zeros_like(dirs))
    n2 = (d * d).sum(-1, keepdim=True)
    good = n2 > 0
    safe = torch.where(good, n2, torch.ones_like(n2))
    return torch.where(good, d * torch.rsqrt(safe), torch.zeros_like(d))


def eval_sh(degree: int, sh: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
    """Raw SH value [N, C] of coefficients ``sh[N, K, C]`` in directions ``dirs[N, 3]`` (any length)."""
    k = (degree + 1) ** 2
    if sh.shape[1] < k:
        raise ValueError(f"degree {degree} needs {k} SH coefficients per channel, got {sh.shape[1]}")
    d = normalize_dirs(dirs.to(sh.dtype))
    basis = sh_basis(degree, d)
    return torch.einsum("nk,nkc->nc", basis, sh[:, :k])


def sh_to_color(degree: int, sh: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
    """Colour ``max(eval_sh + 0.5, 0)`` as 3DGS and gsplat define it."""
    return torch.clamp_min(eval_sh(degree, sh, dirs) + 0.5, 0.0)
