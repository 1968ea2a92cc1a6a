"""EWA projection of 3D Gaussians to 2D conics.

Two implementations of the same maths: :func:`project_gaussians_torch`, vectorised torch
(differentiable by autograd; the reference, also used for non-CPU tensors), and the numba kernels of
:mod:`.proj_kernels` with a hand-written backward pass (:class:`ProjectGaussians`), the CPU fast path.
:func:`project_gaussians` picks one (``backend``). Numerics follow gsplat / 3DGS:

* positions are taken relative to the camera centre in float64 before anything else, so a scene
  1e5 m from the origin keeps its precision; the whole projection runs in float64 and its outputs
  are cast back to the input dtype;
* the Jacobian of the perspective map is evaluated at the mean clamped to the widened frustum
  (``-cx/fx - 0.3 tan(fov_x/2) <= x/z <= (W-cx)/fx + 0.3 tan(fov_x/2)``, i.e. ``|x/z| <= 1.3
  tan(fov_x/2)`` for a centred principal point; same for y);
* ``eps2d`` is added to the 2D covariance; in antialiased mode the opacity is multiplied by
  ``sqrt(max(0.005^2, det_orig / det_blur))``;
* culled: ``z < near``, ``z > far``, ``det <= 0``, opacity below the alpha threshold, a box that
  misses the image, and any Gaussian with a non-finite parameter;
* extent per axis ``ceil(k * sqrt(cov_ii))`` with ``k = min(3.33, sqrt(2 ln(o / threshold)))``
  ("opacity", the default), ``k = 3`` ("3sigma") or a given number ``k``.

Inputs are sanitised before any division (a culled Gaussian at z = 0 gets a zero gradient, not
``0 * inf = NaN``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from ..conventions import FAR_PLANE, NEAR_PLANE
from .constants import ALPHA_THRESHOLD, EPS2D, EXTENT_CAP, FOV_CLAMP_MARGIN

AA_COMPENSATION_FLOOR = 0.005 ** 2
RADIUS_MAX = float(2 ** 30)  # radii are clamped before converting to integers


@dataclass
class Projection:
    means2d: torch.Tensor  # [N, 2] pixel coordinates (pixel centres at +0.5)
    conics: torch.Tensor  # [N, 3] inverse 2D covariance (a, b, c): sigma = a dx^2/2 + b dx dy + c dy^2/2
    depths: torch.Tensor  # [N] camera z
    opacities: torch.Tensor  # [N] opacity after antialiasing compensation (0 when culled)
    radii: torch.Tensor  # [N, 2] int32 box half-sizes in pixels, 0 when culled
    visible: torch.Tensor  # [N] bool
    rel_means: torch.Tensor  # [N, 3] float64 world position minus camera centre
    camera_center: torch.Tensor  # [3] float64


def camera_center(viewmat: torch.Tensor) -> torch.Tensor:
    """Camera centre in world coordinates (float64) of a world->camera 4x4."""
    v = viewmat.detach().to(torch.float64)
    return -(v[:3, :3].T @ v[:3, 3])


def quat_to_rotmat(q: torch.Tensor) -> torch.Tensor:
    """Unit wxyz quaternions [N, 4] -> rotation matrices [N, 3, 3]."""
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=-1).reshape(q.shape[:-1] + (3, 3))


def normalize_quats(quats: torch.Tensor) -> torch.Tensor:
    """Unit quaternions; zero, tiny or non-finite ones become the identity (finite gradients)."""
    ok = torch.isfinite(quats).all(-1, keepdim=True)
    ident = torch.zeros_like(quats)
    ident[..., 0] = 1.0
    q = torch.where(ok, quats, ident)
    n2 = (q * q).sum(-1, keepdim=True)
    good = n2 > 1e-30
    q = torch.where(good, q, ident)
    n2 = torch.where(good, n2, torch.ones_like(n2))
    return q * torch.rsqrt(n2)


def extent_factor(extent, opac: torch.Tensor, alpha_threshold: float) -> torch.Tensor:
    if isinstance(extent, (int, float)) and not isinstance(extent, bool):
        return torch.full_like(opac, float(extent))
    if extent == "3sigma":
        return torch.full_like(opac, 3.0)
    if extent == "opacity":
        cap = EXTENT_CAP if alpha_threshold >= ALPHA_THRESHOLD else math.sqrt(2.0 * math.log(1.0 / alpha_threshold))
        ratio = torch.clamp_min(opac / alpha_threshold, 1.0)
        return torch.clamp_max(torch.sqrt(2.0 * torch.log(ratio)), cap)
    raise ValueError(f"extent must be 'opacity', '3sigma' or a number, got {extent!r}")


def project_gaussians_torch(means, quats, scales, opacities, viewmat, K, width: int, height: int, *,
                            near: float = NEAR_PLANE, far: float = FAR_PLANE, eps2d: float = EPS2D, antialiased: bool = False,
                            extent="opacity", alpha_threshold: float = ALPHA_THRESHOLD,
                            finite_mask: torch.Tensor | None = None) -> Projection:
    """The vectorised torch projection (reference; gradients by autograd)."""
    n = means.shape[0]
    dtype = means.dtype
    f64 = torch.float64
    ok = (torch.isfinite(means).all(-1) & torch.isfinite(scales).all(-1) & torch.isfinite(opacities)
          & torch.isfinite(quats).all(-1))
    if finite_mask is not None:
        ok = ok & finite_mask
    okc = ok[:, None]

    m = torch.where(okc, means, torch.zeros_like(means)).to(f64)
    s = torch.where(okc, scales, torch.zeros_like(scales)).to(f64)
    o = torch.where(ok, opacities, torch.zeros_like(opacities)).to(f64)
    q = normalize_quats(quats.to(f64))

    c = camera_center(viewmat)
    rv = viewmat.detach().to(f64)[:3, :3]
    rel = m - c
    p = rel @ rv.T
    x, y, z = p.unbind(-1)
    in_depth = ok & (z >= near) & (z <= far)
    zs = torch.where(in_depth, z, torch.ones_like(z))
    xs = torch.where(in_depth, x, torch.zeros_like(x))
    ys = torch.where(in_depth, y, torch.zeros_like(y))

    Kd = K.detach().to(f64)
    fx, fy, cx, cy = (float(Kd[0, 0]), float(Kd[1, 1]), float(Kd[0, 2]), float(Kd[1, 2]))
    tan_fovx, tan_fovy = 0.5 * width / fx, 0.5 * height / fy
    lim_x_pos, lim_x_neg = (width - cx) / fx + FOV_CLAMP_MARGIN * tan_fovx, cx / fx + FOV_CLAMP_MARGIN * tan_fovx
    lim_y_pos, lim_y_neg = (height - cy) / fy + FOV_CLAMP_MARGIN * tan_fovy, cy / fy + FOV_CLAMP_MARGIN * tan_fovy
    rz = 1.0 / zs
    tx = zs * torch.clamp(xs * rz, -lim_x_neg, lim_x_pos)
    ty = zs * torch.clamp(ys * rz, -lim_y_neg, lim_y_pos)
    rz2 = rz * rz
    zero = torch.zeros_like(rz)
    J = torch.stack([fx * rz, zero, -fx * tx * rz2, zero, fy * rz, -fy * ty * rz2], -1).reshape(n, 2, 3)

    Rq = quat_to_rotmat(q)
    M = Rq * s[:, None, :]  # R S
    A = (J @ rv) @ M  # [N, 2, 3]
    cov = A @ A.transpose(1, 2)
    c00, c01, c11 = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
    det_orig = c00 * c11 - c01 * c01
    b00, b11 = c00 + eps2d, c11 + eps2d
    det = b00 * b11 - c01 * c01
    det_ok = det > 0
    det_s = torch.where(det_ok, det, torch.ones_like(det))
    if antialiased:
        comp = torch.sqrt(torch.clamp_min(det_orig / det_s, AA_COMPENSATION_FLOOR))
        o = o * comp
    inv = 1.0 / det_s
    conics = torch.stack([b11 * inv, -c01 * inv, b00 * inv], -1)
    mean2d = torch.stack([fx * xs * rz + cx, fy * ys * rz + cy], -1)

    with torch.no_grad():
        valid = in_depth & det_ok & (o >= alpha_threshold)
        k = extent_factor(extent, torch.where(valid, o, torch.ones_like(o)), alpha_threshold)
        sx = torch.sqrt(torch.clamp_min(torch.where(valid, b00, zero), 0.0))
        sy = torch.sqrt(torch.clamp_min(torch.where(valid, b11, zero), 0.0))
        rx = torch.clamp(torch.ceil(k * sx), 0.0, RADIUS_MAX)
        ry = torch.clamp(torch.ceil(k * sy), 0.0, RADIUS_MAX)
        mx, my = mean2d[:, 0], mean2d[:, 1]
        inside = (mx + rx > 0) & (mx - rx < width) & (my + ry > 0) & (my - ry < height)
        valid = valid & inside & ((rx > 0) | (ry > 0)) & torch.isfinite(mx) & torch.isfinite(my)
        radii = torch.stack([rx, ry], -1).to(torch.int32) * valid[:, None].to(torch.int32)

    o_out = torch.where(valid, o, torch.zeros_like(o))
    return Projection(means2d=mean2d.to(dtype), conics=conics.to(dtype), depths=zs.to(dtype),
                      opacities=o_out.to(dtype), radii=radii, visible=valid, rel_means=rel,
                      camera_center=c)


def _extent_params(extent, alpha_threshold: float) -> tuple[int, float, float]:
    """(mode, k, cap) for the kernels; the same choices and errors as :func:`extent_factor`."""
    from . import proj_kernels as pk

    if isinstance(extent, (int, float)) and not isinstance(extent, bool):
        return pk.EXTENT_NUMBER, float(extent), 0.0
    if extent == "3sigma":
        return pk.EXTENT_NUMBER, 3.0, 0.0
    if extent == "opacity":
        cap = EXTENT_CAP if alpha_threshold >= ALPHA_THRESHOLD else math.sqrt(2.0 * math.log(1.0 / alpha_threshold))
        return pk.EXTENT_OPACITY, 0.0, cap
    raise ValueError(f"extent must be 'opacity', '3sigma' or a number, got {extent!r}")


def _arr(t: torch.Tensor) -> np.ndarray:
    """A contiguous numpy view (copy only when needed) of a float32/float64 tensor; others as float64."""
    t = t.detach().cpu()
    if t.dtype not in (torch.float32, torch.float64):
        t = t.to(torch.float64)
    return np.ascontiguousarray(t.numpy())


def _np_dtype(dtype: torch.dtype):
    return np.float32 if dtype == torch.float32 else np.float64


class ProjectGaussians(torch.autograd.Function):
    """Numba projection: (means, quats, scales, opacities) -> (means2d, conics, depths, opacities,
    rel_means, radii, visible); gradients by :func:`proj_kernels.project_bwd`. The kernels read
    float32 or float64 storage directly and compute in float64."""

    @staticmethod
    def forward(ctx, means, quats, scales, opacities, cam_args, fwd_args, finite_mask):
        from . import proj_kernels as pk
        from .numba_scope import KernelScope

        n = means.shape[0]
        dtype = means.dtype
        nd = _np_dtype(dtype)
        arrays = (_arr(means), _arr(quats), _arr(scales), _arr(opacities), finite_mask)
        m2d = np.empty((n, 2), nd)
        conic = np.empty((n, 3), nd)
        depth = np.empty(n, nd)
        opac = np.empty(n, nd)
        radii = np.empty((n, 2), np.int32)
        visible = np.empty(n, np.bool_)
        rel = np.empty((n, 3))
        with KernelScope(chunk=0, items=n):
            pk.project_fwd(*arrays, *cam_args, *fwd_args, m2d, conic, depth, opac, radii, visible, rel)
        ctx.save_for_backward(means, quats, scales, opacities)
        ctx.finite_mask = finite_mask
        ctx.cam_args = cam_args
        ctx.visible = visible
        radii_t = torch.from_numpy(radii).to(means.device)
        visible_t = torch.from_numpy(visible).to(means.device)
        ctx.mark_non_differentiable(radii_t, visible_t)

        def out(a):
            return torch.from_numpy(a).to(device=means.device, dtype=dtype)

        return (out(m2d), out(conic), out(depth), out(opac), torch.from_numpy(rel).to(means.device), radii_t,
                visible_t)

    @staticmethod
    def backward(ctx, g_m2d, g_conic, g_depth, g_opac, g_rel, _g_radii, _g_visible):
        from . import proj_kernels as pk
        from .numba_scope import KernelScope

        tensors = ctx.saved_tensors
        n = tensors[0].shape[0]
        d = [np.empty((n,) + tuple(t.shape[1:]), _np_dtype(t.dtype)) for t in tensors]
        grads = [_arr(g) for g in (g_m2d, g_conic, g_depth, g_opac, g_rel)]
        with KernelScope(chunk=0, items=n):
            pk.project_bwd(*[_arr(t) for t in tensors], ctx.finite_mask, *ctx.cam_args, ctx.visible, *grads, *d)
        return tuple(torch.from_numpy(a).to(device=t.device, dtype=t.dtype) for a, t in zip(d, tensors)) + (
            None, None, None)


def project_gaussians_numba(means, quats, scales, opacities, viewmat, K, width: int, height: int, *,
                            near: float = NEAR_PLANE, far: float = FAR_PLANE, eps2d: float = EPS2D, antialiased: bool = False,
                            extent="opacity", alpha_threshold: float = ALPHA_THRESHOLD,
                            finite_mask: torch.Tensor | None = None) -> Projection:
    """The numba projection (CPU tensors): same outputs as :func:`project_gaussians_torch`."""
    n = means.shape[0]
    mode, ext_k, cap = _extent_params(extent, alpha_threshold)
    c = camera_center(viewmat)
    rv = viewmat.detach().to(torch.float64).cpu()[:3, :3].contiguous().numpy()
    Kd = K.detach().to(torch.float64)
    fx, fy, cx, cy = (float(Kd[0, 0]), float(Kd[1, 1]), float(Kd[0, 2]), float(Kd[1, 2]))
    tan_fovx, tan_fovy = 0.5 * width / fx, 0.5 * height / fy
    lim_x_pos, lim_x_neg = (width - cx) / fx + FOV_CLAMP_MARGIN * tan_fovx, cx / fx + FOV_CLAMP_MARGIN * tan_fovx
    lim_y_pos, lim_y_neg = (height - cy) / fy + FOV_CLAMP_MARGIN * tan_fovy, cy / fy + FOV_CLAMP_MARGIN * tan_fovy
    cam_args = (rv, np.ascontiguousarray(c.cpu().numpy()), fx, fy, cx, cy, lim_x_neg, lim_x_pos, lim_y_neg,
                lim_y_pos, float(near), float(far), float(eps2d), bool(antialiased), AA_COMPENSATION_FLOOR)
    fwd_args = (mode, ext_k, cap, float(alpha_threshold), float(width), float(height), RADIUS_MAX)
    fm = (np.ones(n, np.bool_) if finite_mask is None
          else np.ascontiguousarray(finite_mask.detach().cpu().numpy().astype(np.bool_)))
    m2d, conics, depths, opac, rel, radii, visible = ProjectGaussians.apply(
        means, quats, scales, opacities, cam_args, fwd_args, fm)
    return Projection(means2d=m2d, conics=conics, depths=depths, opacities=opac, radii=radii, visible=visible,
                      rel_means=rel, camera_center=c)


def use_numba(*tensors) -> bool:
    """The numba kernels serve CPU float32/float64 tensors."""
    return all(t.device.type == "cpu" and t.dtype in (torch.float32, torch.float64) for t in tensors)


def project_gaussians(means, quats, scales, opacities, viewmat, K, width: int, height: int, *,
                      near: float = NEAR_PLANE, far: float = FAR_PLANE, eps2d: float = EPS2D, antialiased: bool = False,
                      extent="opacity", alpha_threshold: float = ALPHA_THRESHOLD,
                      finite_mask: torch.Tensor | None = None, backend: str = "auto") -> Projection:
    """Project Gaussians (see the module docstring). ``backend``: ``"numba"``, ``"torch"`` or
    ``"auto"`` (numba for CPU float tensors, else torch). Differentiable either way."""
    if backend not in ("auto", "numba", "torch"):
        raise ValueError(f"projection backend must be auto, numba or torch, got {backend!r}")
    if backend == "auto":
        backend = "numba" if use_numba(means, quats, scales, opacities) else "torch"
    fn = project_gaussians_numba if backend == "numba" else project_gaussians_torch
    return fn(means, quats, scales, opacities, viewmat, K, width, height, near=near, far=far, eps2d=eps2d,
              antialiased=antialiased, extent=extent, alpha_threshold=alpha_threshold, finite_mask=finite_mask)
