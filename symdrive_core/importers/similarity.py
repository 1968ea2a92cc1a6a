"""Similarity transforms ``x' = s R x + t`` of cameras and 3D Gaussians, SH colours included.

A similarity is kept as one 4x4 matrix ``[[s R, t], [0, 1]]``. Applied to a splat cloud it moves
the means, turns the rotations, adds ``log s`` to the log-scales and rotates the view-dependent
colour: the SH coefficients of each degree ``l >= 1`` are multiplied by the (2l+1)x(2l+1) matrix
that maps the basis of that degree under the rotation. That matrix is found exactly by least
squares on basis values at fixed sample directions (degree ``l`` harmonics span a rotation-invariant
space, so the fit has zero residual), with the basis of :mod:`symdrive_core.splat.sh` itself.
"""

from __future__ import annotations

import numpy as np

from ..gaussians import Gaussians
from ..rotations import matrix_to_quat, quat_multiply


def make_similarity(scale: float, R: np.ndarray, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = float(scale) * np.asarray(R, dtype=np.float64)
    T[:3, 3] = np.asarray(t, dtype=np.float64)
    return T


def decompose(T: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(s, R, t) of a similarity 4x4 (``s > 0``, ``R`` a proper rotation)."""
    T = np.asarray(T, dtype=np.float64)
    A = T[:3, :3]
    s = float(np.cbrt(np.linalg.det(A)))
    if not np.isfinite(s) or s <= 0:
        raise ValueError("not a similarity with positive scale (det <= 0)")
    R = A / s
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6):
        raise ValueError("not a similarity: the 3x3 block is not a scaled rotation")
    return s, R, T[:3, 3].copy()


def apply_points(T: np.ndarray, points) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    return p @ np.asarray(T)[:3, :3].T + np.asarray(T)[:3, 3]


def apply_camera(T: np.ndarray, c2w: np.ndarray) -> np.ndarray:
    """Camera-to-world (rigid) after the similarity: rotation turned by R, centre moved by T."""
    s, R, t = decompose(T)
    out = np.eye(4)
    out[:3, :3] = R @ np.asarray(c2w, dtype=np.float64)[:3, :3]
    out[:3, 3] = s * R @ np.asarray(c2w, dtype=np.float64)[:3, 3] + t
    return out


def _fibonacci_dirs(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = np.pi * (1.0 + 5.0 ** 0.5) * i
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)


def _basis(degree: int, dirs: np.ndarray) -> np.ndarray:
    import torch

    from ..splat.sh import sh_basis

    return sh_basis(degree, torch.as_tensor(dirs, dtype=torch.float64)).numpy()


def sh_rotation(R: np.ndarray, degree: int) -> list[np.ndarray]:
    """Per degree ``l = 1..degree``, the matrix ``D_l`` with ``c'_l = D_l @ c_l``: the colour of
    the rotated function in direction ``d`` equals the original's in ``R^T d``."""
    R = np.asarray(R, dtype=np.float64)
    dirs = _fibonacci_dirs(64)
    A = _basis(degree, dirs)  # Y(d)
    B = _basis(degree, dirs @ R)  # Y(R^T d), rows are (R^T d_i)^T = d_i^T R
    out = []
    for l in range(1, degree + 1):
        sl = slice(l * l, (l + 1) * (l + 1))
        # Y_l(R^T d) = Y_l(d) M  =>  f'(d) = Y_l(R^T d) c = Y_l(d) (M c): D_l = M
        M, *_ = np.linalg.lstsq(A[:, sl], B[:, sl], rcond=None)
        out.append(M)
    return out


def rotate_sh(sh: np.ndarray, R: np.ndarray) -> np.ndarray:
    """SH coefficients ``sh[N, K, 3]`` of colours seen along world directions, after the world
    is rotated by ``R`` (degree 0 unchanged)."""
    sh = np.asarray(sh)
    k = sh.shape[1]
    degree = int(round(np.sqrt(k))) - 1
    if degree < 1:
        return sh.copy()
    out = sh.astype(np.float64, copy=True)
    for l, D in enumerate(sh_rotation(R, degree), start=1):
        sl = slice(l * l, (l + 1) * (l + 1))
        out[:, sl, :] = np.einsum("ij,njc->nic", D, out[:, sl, :])
    return out.astype(sh.dtype)


def transform_gaussians(g: Gaussians, T: np.ndarray) -> Gaussians:
    """``g`` after the similarity ``T``: means, rotations, log-scales, normals and SH colours."""
    s, R, t = decompose(T)
    qR = matrix_to_quat(R)
    quats = quat_multiply(qR[None], g.quats.astype(np.float64))
    return Gaussians(
        means=apply_points(T, g.means).astype(np.float32),
        quats=quats.astype(np.float32),
        log_scales=(g.log_scales.astype(np.float64) + np.log(s)).astype(np.float32),
        opacity_logits=g.opacity_logits.copy(),
        sh=rotate_sh(g.sh, R),
        normals=None if g.normals is None else (g.normals.astype(np.float64) @ R.T).astype(np.float32),
        extra=dict(g.extra),
    )
