"""Real spherical harmonics up to degree 3 (the 3DGS basis and constants), in torch.

``eval_sh`` returns the raw SH value per channel; the colour the rasterizer uses is
``max(eval_sh + 0.5, 0)`` (:func:`sh_to_color`). Directions are normalised inside (a zero direction
gives a zero vector, never NaN). Coefficients are ``sh[N, K, 3]`` with ``K >= (degree + 1)**2``.

``eval_sh`` / ``sh_to_color`` run the numba kernels of :mod:`.proj_kernels` (hand-written backward,
:class:`SHColor`) for CPU float tensors and the torch versions (``eval_sh_torch`` /
``sh_to_color_torch``, the reference, differentiable by autograd) otherwise or when
``backend="torch"``.
"""

from __future__ import annotations

import numpy as np
import torch

from ..gaussians import SH_C0, SH_C1, SH_C2, SH_C3


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


def _check(degree: int, sh: torch.Tensor) -> int:
    if not 0 <= degree <= 3:
        raise ValueError(f"SH degree must be 0..3, got {degree}")
    k = (degree + 1) ** 2
    if sh.shape[1] < k:
        raise ValueError(f"degree {degree} needs {k} SH coefficients per channel, got {sh.shape[1]}")
    return k


def eval_sh_torch(degree: int, sh: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
    """Torch reference of :func:`eval_sh`."""
    k = _check(degree, sh)
    d = normalize_dirs(dirs.to(sh.dtype))
    basis = sh_basis(degree, d)
    return torch.einsum("nk,nkc->nc", basis, sh[:, :k])


def sh_to_color_torch(degree: int, sh: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
    """Torch reference of :func:`sh_to_color`."""
    return torch.clamp_min(eval_sh_torch(degree, sh, dirs) + 0.5, 0.0)


class SHColor(torch.autograd.Function):
    """Numba SH evaluation: (sh [N,K,C], dirs [N,3]) -> [M,C] in sh's dtype (clamp: the colour) for
    the rows ``rows`` (int64 numpy, None: all N). float32 or float64 storage is read directly, the
    arithmetic is float64; the gradients come back as full [N,...] arrays (zero rows where not picked)
    without a gathered copy of the coefficients either way."""

    @staticmethod
    def forward(ctx, sh, dirs, degree, clamp, rows=None):
        from . import proj_kernels as pk
        from .numba_scope import KernelScope
        from .projection import _arr, _np_dtype

        n = sh.shape[0]
        rows = np.arange(n, dtype=np.int64) if rows is None else rows
        out = np.empty((rows.shape[0], sh.shape[2]), _np_dtype(sh.dtype))
        with KernelScope(chunk=0, items=rows.shape[0]):
            pk.sh_fwd(int(degree), _arr(sh), _arr(dirs), rows, bool(clamp), out)
        ctx.save_for_backward(sh, dirs)
        ctx.opts = (int(degree), bool(clamp), rows)
        return torch.from_numpy(out).to(device=sh.device, dtype=sh.dtype)

    @staticmethod
    def backward(ctx, g_out):
        from . import proj_kernels as pk
        from .numba_scope import KernelScope
        from .projection import _arr, _np_dtype

        sh, dirs = ctx.saved_tensors
        degree, clamp, rows = ctx.opts
        n = sh.shape[0]
        pos = np.full(n, -1, np.int64)
        pos[rows] = np.arange(rows.shape[0])
        d_sh = np.empty(tuple(sh.shape), _np_dtype(sh.dtype))
        d_dirs = np.empty(tuple(dirs.shape), _np_dtype(dirs.dtype))
        with KernelScope(chunk=0, items=n):
            pk.sh_bwd(degree, _arr(sh), _arr(dirs), pos, clamp, _arr(g_out), d_sh, d_dirs)
        return (torch.from_numpy(d_sh).to(device=sh.device, dtype=sh.dtype),
                torch.from_numpy(d_dirs).to(device=dirs.device, dtype=dirs.dtype), None, None, None)


def _use_numba(sh: torch.Tensor, dirs: torch.Tensor, backend: str) -> bool:
    if backend not in ("auto", "numba", "torch"):
        raise ValueError(f"SH backend must be auto, numba or torch, got {backend!r}")
    if backend == "auto":
        return all(t.device.type == "cpu" and t.dtype in (torch.float32, torch.float64) for t in (sh, dirs))
    return backend == "numba"


def eval_sh(degree: int, sh: torch.Tensor, dirs: torch.Tensor, backend: str = "auto") -> torch.Tensor:
    """Raw SH value [N, C] of coefficients ``sh[N, K, C]`` in directions ``dirs[N, 3]`` (any length)."""
    if not _use_numba(sh, dirs, backend):
        return eval_sh_torch(degree, sh, dirs)
    _check(degree, sh)
    return SHColor.apply(sh, dirs, int(degree), False)


def sh_to_color(degree: int, sh: torch.Tensor, dirs: torch.Tensor, backend: str = "auto",
                rows: np.ndarray | None = None) -> torch.Tensor:
    """Colour ``max(eval_sh + 0.5, 0)`` as 3DGS and gsplat define it; ``rows`` (int64 indices): only
    those Gaussians, same as ``sh_to_color(degree, sh[rows], dirs[rows])`` without the copies."""
    if not _use_numba(sh, dirs, backend):
        if rows is not None:
            idx = torch.from_numpy(rows).to(sh.device)
            sh, dirs = sh[idx], dirs[idx]
        return sh_to_color_torch(degree, sh, dirs)
    _check(degree, sh)
    return SHColor.apply(sh, dirs, int(degree), True, rows)
