"""Public rasterizer: ``rasterize(...)`` with a hand-written tile-based backward pass.

The split follows gsplat: projection (:class:`.projection.ProjectGaussians`), SH evaluation
(:class:`.sh.SHColor`) and per-pixel compositing (:class:`RasterizePixels`) are each a
``torch.autograd.Function`` whose forward and hand-written backward are numba kernels
(:mod:`symdrive_core.splat.proj_kernels`, :mod:`symdrive_core.splat.kernels`); the torch backend runs
the vectorised torch versions of all three instead (autograd gives their gradients).

Backends: ``"numba"`` (CPU kernels), ``"torch"`` (the vectorised reference of
:mod:`symdrive_core.splat.reference`, differentiable by autograd), ``"gsplat"`` (gsplat's CUDA
``rasterization``; only for CUDA tensors) and ``"auto"`` (gsplat when the tensors are on CUDA and
gsplat imports, else numba).
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np
import torch

from ..conventions import FAR_PLANE, NEAR_PLANE
from . import kernels
from .constants import ALPHA_THRESHOLD, EPS2D, TILE_SIZE
from .numba_scope import KernelScope as _KernelScope
from .projection import camera_center, project_gaussians, use_numba
from .sh import sh_to_color

# parallel chunk of the compositing kernels: small enough that uneven tiles balance across cores, large
# enough for their per-Gaussian packing loop (in the same kernel, so handed out in the same chunks),
# which chunks of 2 slowed by about a fifth (measured at 1M Gaussians, 1280x720, 2 threads)
KERNEL_CHUNK = 16
_scratch = threading.local()


def _record_buffer(m: int, C: int) -> np.ndarray:
    """Scratch [m, R_COLOR + C] float64 for the compositing kernels' packed records, kept per thread
    between calls (a kernel call fills it and is done with it on return): a fresh array of that size
    every frame costs more in page faults than the packing itself (~20 ms at 1M Gaussians)."""
    n = m * (kernels.R_COLOR + C)
    buf = getattr(_scratch, "records", None)
    if buf is None or buf.shape[0] < n:
        buf = _scratch.records = np.empty(n)
    return buf[:n].reshape(m, kernels.R_COLOR + C)


@dataclass
class TileBins:
    offsets: np.ndarray  # [n_tiles + 1] int64
    ids: np.ndarray  # [n_isect] int32, indices into the visible Gaussians, front to back per tile
    row_start: np.ndarray  # [m + 1] int64: Gaussian g's list positions are rows[row_start[g]:row_start[g+1]]
    rows: np.ndarray  # [n_isect] int64, increasing per Gaussian (both empty when binned with with_rows=False)
    tiles_x: int
    tiles_y: int
    tile_size: int = TILE_SIZE

    @property
    def n_isect(self) -> int:
        return int(self.offsets[-1])


def bin_gaussians(means2d: torch.Tensor, radii: torch.Tensor, depths: torch.Tensor, width: int, height: int,
                  tile_size: int = TILE_SIZE, with_rows: bool = True, conics: torch.Tensor | None = None,
                  opacities: torch.Tensor | None = None, threshold: float = ALPHA_THRESHOLD) -> TileBins:
    """Tile lists for (visible) Gaussians, each list sorted by depth (ties: lower index first).

    Every tile of a Gaussian's rectangle (``radii``), or, given its ``conics`` and ``opacities`` (and
    the compositing ``threshold``), only the tiles where the compositing kernels can use it
    (:func:`.kernels.ellipse_rects`): the image is the same, with fewer tile-Gaussian pairs.

    ``with_rows=False`` skips each Gaussian's list positions (``row_start``, ``rows``: only the
    backward pass reads them), for a frame rendered without gradients.
    """
    tiles_x = (width + tile_size - 1) // tile_size
    tiles_y = (height + tile_size - 1) // tile_size
    m2d = _np(means2d)
    rad = _np(radii)
    if m2d.shape[0] == 0:
        return TileBins(np.zeros(tiles_x * tiles_y + 1, np.int64), np.zeros(0, np.int32), np.zeros(1, np.int64),
                        np.zeros(0, np.int64), tiles_x, tiles_y, tile_size)
    order = kernels.depth_order(_np(depths))
    with _KernelScope(chunk=0, items=m2d.shape[0]):
        if conics is None or tile_size != kernels.TILE:
            rects = kernels.tile_rects(m2d, rad, order, tile_size, tiles_x, tiles_y)
            masks = np.zeros(0, np.uint64)
        else:
            rects, masks = kernels.ellipse_rects(m2d, rad, _np(conics), _np(opacities), order, float(threshold),
                                                 width, height, tile_size, tiles_x, tiles_y)
        offsets, ids, row_start, rows = kernels.bin_tiles(order, rects, tiles_x, tiles_y, masks, with_rows)
    return TileBins(offsets, ids, row_start, rows, tiles_x, tiles_y, tile_size)


def _np(t: torch.Tensor) -> np.ndarray:
    return np.ascontiguousarray(t.detach().cpu().numpy())


def _take_np(a: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``a[rows]`` for a 2D array by the parallel kernel."""
    out = np.empty((rows.shape[0], a.shape[1]), a.dtype)
    with _KernelScope(chunk=0, items=rows.shape[0]):
        kernels.take_rows(a, rows, out)
    return out


class RasterizePixels(torch.autograd.Function):
    """2D Gaussians -> (features [H,W,C], alpha [H,W], instance [H,W,G]) with the numba kernels."""

    @staticmethod
    def forward(ctx, means2d, conics, opacities, colors, groups, n_groups, bins, width, height, threshold):
        dtype = colors.dtype
        C = colors.shape[1]
        G = max(int(n_groups), 0)
        np_dtype = np.float64 if dtype == torch.float64 else np.float32
        out_color = np.zeros((height, width, C), np_dtype)
        out_T = np.ones((height, width), np.float64)
        out_inst = np.zeros((height, width, max(G, 1)), np_dtype)
        out_last = np.zeros((height, width), np.int64)
        grp = _np(groups.to(torch.int64)) if G > 0 else np.zeros(0, np.int64)
        args = (_np(means2d), _np(conics), _np(opacities), _np(colors), grp, G, bins.offsets, bins.ids,
                int(width), int(height), bins.tiles_x, bins.tile_size, float(threshold))
        # about 256 pixel evaluations per intersection: small jobs stay on one thread
        with _KernelScope(chunk=KERNEL_CHUNK, items=bins.n_isect, serial_below=8192):
            kernels.rasterize_fwd(*args, out_color, out_T, out_inst, out_last, _record_buffer(means2d.shape[0], C))
        ctx.args = args
        ctx.bins = bins
        ctx.outs = (out_color, out_T, out_inst, out_last)
        ctx.shapes = (means2d.shape[0], C, G, dtype, means2d.device)
        color = torch.from_numpy(out_color).to(means2d.device)
        alpha = torch.from_numpy((1.0 - out_T).astype(np_dtype)).to(means2d.device)
        inst = torch.from_numpy(out_inst[..., :G].copy()).to(means2d.device)
        return color, alpha, inst

    @staticmethod
    def backward(ctx, g_color, g_alpha, g_inst):
        m, C, G, dtype, device = ctx.shapes
        args = ctx.args
        out_color, out_T, out_inst, out_last = ctx.outs
        H, W = out_T.shape
        np_dtype = np.float64 if dtype == torch.float64 else np.float32

        def grad_np(g, shape):
            if g is None:
                return np.zeros(shape, np_dtype)
            return np.ascontiguousarray(g.detach().cpu().numpy().astype(np_dtype, copy=False))

        gc = grad_np(g_color, (H, W, C))
        ga = grad_np(g_alpha, (H, W))
        gi = grad_np(g_inst, (H, W, G)) if G > 0 else np.zeros((H, W, 1), np_dtype)
        n_isect = args[7].shape[0]
        r = np.zeros((n_isect, 6 + C), np_dtype)  # one row per intersection: 2D mean, conic, opacity, colour
        with _KernelScope(chunk=KERNEL_CHUNK, items=n_isect, serial_below=8192):
            kernels.rasterize_bwd(*args, out_color, out_T, out_inst, out_last, gc, ga, gi,
                                  r[:, 0:2], r[:, 2:5], r[:, 5], r[:, 6:], _record_buffer(m, C))
        bins = ctx.bins
        if bins.row_start.shape[0] != m + 1:
            raise RuntimeError("the tile lists were binned with with_rows=False: no backward pass")
        g_m2d = np.empty((m, 2), np_dtype)
        g_conic = np.empty((m, 3), np_dtype)
        g_opac = np.empty(m, np_dtype)
        g_col = np.empty((m, C), np_dtype)
        with _KernelScope(chunk=0, items=m):
            kernels.reduce_rows(bins.row_start, bins.rows, r, g_m2d, g_conic, g_opac, g_col)

        def t(a):
            return torch.from_numpy(a).to(device=device, dtype=dtype)

        return t(g_m2d), t(g_conic), t(g_opac), t(g_col), None, None, None, None, None, None


class TakeRows(torch.autograd.Function):
    """``[t[rows] for t in tensors]`` (float, first dim N) by a numba kernel; the backward writes each
    full [N, ...] gradient in one pass (zeros where not taken) instead of zero-filling and scattering."""

    @staticmethod
    def forward(ctx, rows, pos, *tensors):
        ctx.pos = pos
        ctx.shapes = [(t.shape, t.dtype, t.device) for t in tensors]
        out = []
        with _KernelScope(chunk=0, items=rows.shape[0]):
            for t in tensors:
                src = _np(t).reshape(t.shape[0], math.prod(t.shape[1:]))
                dst = np.empty((rows.shape[0], src.shape[1]), src.dtype)
                kernels.take_rows(src, rows, dst)
                out.append(torch.from_numpy(dst.reshape((rows.shape[0],) + tuple(t.shape[1:]))).to(t.device))
        return tuple(out)

    @staticmethod
    def backward(ctx, *grads):
        out = []
        with _KernelScope(chunk=0, items=ctx.pos.shape[0]):
            for g, (shape, dtype, device) in zip(grads, ctx.shapes):
                if g is None:
                    out.append(None)
                    continue
                src = _np(g.to(dtype)).reshape(g.shape[0], math.prod(shape[1:]))
                dst = np.empty((shape[0], src.shape[1]), src.dtype)
                kernels.put_rows(src, ctx.pos, dst)
                out.append(torch.from_numpy(dst.reshape(shape)).to(device))
        return (None, None, *out)


def _rows_finite(a: torch.Tensor, backend: str) -> torch.Tensor:
    """Bool [N]: every entry of row i finite (numba kernel on the CPU path)."""
    if a.shape[0] == 0:
        return torch.ones(0, dtype=torch.bool, device=a.device)
    if backend == "numba" and use_numba(a):
        from . import proj_kernels
        from .projection import _arr

        out = np.empty(a.shape[0], np.bool_)
        with _KernelScope(chunk=0, items=a.shape[0]):
            proj_kernels.rows_finite(_arr(a), out)
        return torch.from_numpy(out).to(a.device)
    return torch.isfinite(a).all(-1)


def resolve_backend(backend: str, device: torch.device) -> str:
    if backend == "auto":
        if device.type == "cuda":
            try:
                import gsplat  # noqa: F401
                return "gsplat"
            except ImportError:
                pass
        return "numba"
    if backend not in ("numba", "torch", "gsplat"):
        raise ValueError(f"backend must be auto, numba, torch or gsplat, got {backend!r}")
    return backend


def _rasterize_gsplat(means, quats, scales, opacities, colors, viewmat, K, width, height, *, background,
                      sh_degree, near, far, eps2d, antialiased, render_depth, groups, n_groups):
    """Adapter to gsplat's CUDA ``rasterization`` (same conventions; only for CUDA tensors).

    Instance groups travel as extra one-hot colour channels (RGB only: SH colours are evaluated here
    first when groups are asked for).
    """
    import gsplat

    G = int(n_groups) if groups is not None else 0
    if G > 0 and colors.dim() == 3:
        cam = camera_center(viewmat).to(device=means.device, dtype=torch.float64)
        deg = int(round(math.sqrt(colors.shape[1]))) - 1 if sh_degree is None else int(sh_degree)
        colors, sh_degree = sh_to_color(deg, colors, means.double() - cam).to(means.dtype), None
    n_color = colors.shape[-1]
    if G > 0:
        onehot = torch.nn.functional.one_hot(groups.clamp_min(0), G).to(colors.dtype)
        colors = torch.cat([colors, onehot * (groups >= 0)[:, None].to(colors.dtype)], -1)
    render, alphas, meta = gsplat.rasterization(
        means, quats, scales, opacities, colors, viewmat[None], K[None], width, height, near_plane=near,
        far_plane=far, eps2d=eps2d, sh_degree=sh_degree if colors.dim() == 3 else None,
        rasterize_mode="antialiased" if antialiased else "classic",
        render_mode="RGB+ED" if render_depth else "RGB")
    render, alpha = render[0], alphas[0]
    rgb = render[..., :n_color]
    if background is not None:
        rgb = rgb + (1.0 - alpha) * torch.as_tensor(background, dtype=rgb.dtype, device=rgb.device)
    info = {"radii": meta.get("radii"), "means2d": meta.get("means2d"), "depths": meta.get("depths"),
            "n_isect": int(meta["isect_ids"].numel()) if "isect_ids" in meta else None, "backend": "gsplat",
            "meta": meta, "width": width, "height": height}
    if render_depth:
        info["depth"] = render[..., -1:]
    if G > 0:
        info["instance"] = render[..., n_color:n_color + G]
    return rgb, alpha, info


LOW_PRECISION = (torch.float16, torch.bfloat16)


def rasterize(means, quats, scales, opacities, colors, viewmat, K, width: int, height: int, *,
              background=None, sh_degree: int | None = None, near: float = NEAR_PLANE, far: float = FAR_PLANE,
              eps2d: float = EPS2D, antialiased: bool = False, render_depth: bool = False,
              alpha_threshold: float = ALPHA_THRESHOLD, extent="opacity", backend: str = "auto",
              groups: torch.Tensor | None = None, n_groups: int = 0):
    """Render activated Gaussians. Returns ``(rgb [H,W,C], alpha [H,W,1], info)``.

    ``means [N,3]``, ``quats [N,4]`` wxyz (normalised here; zero -> identity), ``scales [N,3]``,
    ``opacities [N]``, ``colors`` either ``[N,C]`` or SH ``[N,K,3]`` (degree ``sh_degree``, default
    the largest that K allows; colour ``max(SH(normalize(mu - camera)) + 0.5, 0)``). ``viewmat``
    world->camera 4x4 (OpenCV), ``K`` 3x3, pixel centres at +0.5. ``background [C]`` is composited
    as ``rgb + (1 - alpha) * background``.

    ``groups [N]`` (int, -1 for none) with ``n_groups > 0`` adds ``info["instance"] [H,W,n_groups]``:
    per group the accumulated ``alpha_i T_i`` of its Gaussians (differentiable).

    ``info``: ``radii [N,2]``, ``means2d [N,2]`` (in the graph: ``retain_grad()`` it for
    densification statistics), ``depths [N]``, ``conics``, ``opacities`` (compensated),
    ``visible [N]``, ``n_isect``, ``depth [H,W,1]`` (alpha-weighted expected camera z, 0 where
    empty) when ``render_depth``, ``bins`` (tile lists), ``backend``.
    """
    if width <= 0 or height <= 0:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    width, height = int(width), int(height)
    low = next((t.dtype for t in (means, quats, scales, opacities, colors, viewmat, K)
                if torch.is_tensor(t) and t.dtype in LOW_PRECISION), None)
    if low is not None:  # rendered in float32, the kernels' narrowest type, and returned as given
        up = [t.float() if torch.is_tensor(t) and t.is_floating_point() else t
              for t in (means, quats, scales, opacities, colors, viewmat, K)]
        rgb, alpha, info = rasterize(*up, width, height, background=background, sh_degree=sh_degree, near=near,
                                     far=far, eps2d=eps2d, antialiased=antialiased, render_depth=render_depth,
                                     alpha_threshold=alpha_threshold, extent=extent, backend=backend,
                                     groups=groups, n_groups=n_groups)
        return rgb.to(low), alpha.to(low), info
    n = means.shape[0]
    device = means.device
    backend = resolve_backend(backend, device)
    if backend == "gsplat":
        return _rasterize_gsplat(means, quats, scales, opacities, colors, viewmat, K, width, height,
                                background=background, sh_degree=sh_degree, near=near, far=far, eps2d=eps2d,
                                antialiased=antialiased, render_depth=render_depth, groups=groups,
                                n_groups=n_groups)

    is_sh = colors.dim() == 3
    if is_sh:
        k = colors.shape[1]
        deg = int(round(math.sqrt(k))) - 1 if sh_degree is None else int(sh_degree)
        if (deg + 1) ** 2 > k:
            raise ValueError(f"sh_degree {deg} needs {(deg + 1) ** 2} coefficients, colors has {k}")
    col_finite = (_rows_finite(colors.reshape(n, -1), backend) if n
                  else torch.ones(0, dtype=torch.bool, device=device))
    proj = project_gaussians(means, quats, scales, opacities, viewmat, K, width, height, near=near, far=far,
                             eps2d=eps2d, antialiased=antialiased, extent=extent,
                             alpha_threshold=alpha_threshold, finite_mask=col_finite, backend=backend)
    G = int(n_groups) if groups is not None else 0
    dtype = means.dtype
    bins = None
    if backend == "numba":
        # the visible rows are read in place by numba passes (SH colour, one gather of the 2D geometry)
        # whose backward writes the full-size gradients once: no [N, K, 3] copies, no zero-fill + scatter
        rows = np.flatnonzero(_np(proj.visible))
        pos = np.full(n, -1, np.int64)
        pos[rows] = np.arange(rows.shape[0])
        take = (proj.means2d, proj.conics, proj.opacities, proj.depths)
        if is_sh:
            feats = sh_to_color(deg, colors, proj.rel_means, backend=backend, rows=rows).to(colors.dtype)
            m2d, conics, opac, depths_v = TakeRows.apply(rows, pos, *take)
        else:
            m2d, conics, opac, depths_v, feats = TakeRows.apply(rows, pos, *take, colors)
        radii_v = _take_np(_np(proj.radii), rows)
        grp = (torch.from_numpy(_take_np(_np(groups.to(torch.int64))[:, None], rows)[:, 0]) if G > 0
               else torch.zeros(0, dtype=torch.int64))
        n_color = feats.shape[1]
        if render_depth:
            feats = torch.cat([feats, depths_v[:, None].to(feats.dtype)], 1)
        feats = feats.to(dtype)
        # a frame with gradients bins each Gaussian only into the tiles its ellipse reaches: the backward's
        # work per tile-Gaussian pair (gradient rows, reduction) repays the binning's extra work, which a
        # forward alone only about breaks even on (measured at 1M Gaussians, 1280x720)
        grad = torch.is_grad_enabled() and any(t.requires_grad for t in (m2d, conics, opac, feats))
        cut = {"conics": conics, "opacities": opac, "threshold": alpha_threshold} if grad else {}
        bins = bin_gaussians(m2d, torch.from_numpy(radii_v), depths_v, width, height, with_rows=grad, **cut)
        n_isect = bins.n_isect
        out, alpha, inst = RasterizePixels.apply(m2d, conics, opac, feats, grp, G, bins, width, height,
                                                 alpha_threshold)
        n_visible = int(rows.shape[0])
    else:
        from .reference import rasterize_pixels_torch

        vis = torch.nonzero(proj.visible, as_tuple=False).squeeze(1)
        if is_sh:
            feats = sh_to_color(deg, colors[vis], proj.rel_means[vis], backend=backend).to(colors.dtype)
        else:
            feats = colors[vis]
        n_color = feats.shape[1]
        depths_v = proj.depths[vis]
        if render_depth:
            feats = torch.cat([feats, depths_v[:, None].to(feats.dtype)], 1)
        feats = feats.to(dtype)
        grp = groups[vis] if G > 0 else torch.zeros(0, dtype=torch.int64, device=device)
        out, alpha, inst, n_isect = rasterize_pixels_torch(proj.means2d[vis], proj.conics[vis], proj.opacities[vis],
                                                           feats, grp, G, width, height, alpha_threshold,
                                                           proj.radii[vis], depths_v)
        n_visible = int(vis.numel())
    alpha = alpha[..., None]
    rgb = out[..., :n_color]
    if background is not None:
        bg = torch.as_tensor(background, dtype=rgb.dtype, device=rgb.device)
        rgb = rgb + (1.0 - alpha) * bg
    info = {"radii": proj.radii, "means2d": proj.means2d, "depths": proj.depths, "conics": proj.conics,
            "opacities": proj.opacities, "visible": proj.visible, "n_isect": n_isect, "bins": bins,
            "n_visible": n_visible, "backend": backend, "camera_center": proj.camera_center,
            "width": width, "height": height}
    if render_depth:
        d = out[..., n_color:n_color + 1]
        info["depth"] = torch.where(alpha > 0, d / torch.where(alpha > 0, alpha, torch.ones_like(alpha)),
                                    torch.zeros_like(d))
    if G > 0:
        info["instance"] = inst
    return rgb, alpha, info
