"""The frame pipeline as it was before the shared per-Gaussian work was fused: only for
``scripts/bench_render.py`` (whole-frame ratio) and ``tests/splat/test_kernels_baseline.py``.

Kept unchanged next to :mod:`.kernels_baseline` so that the benchmark can time a whole baseline frame
in the same process as the current one: torch gathers of the visible rows (the SH coefficients
included) and their index-put backward, a serial per-Gaussian reduction of the gradient rows, the
rectangle arrays in index order (int64) read at random during binning, and float64 copies of the 2D
means. The compositing kernels it calls are :mod:`.kernels_baseline`'s. Only the options the
benchmark uses are supported (no groups, background or depth).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numba import njit, prange

from ..splat import kernels
from ..splat.constants import ALPHA_THRESHOLD, TILE_SIZE
from ..splat.numba_scope import KernelScope
from ..splat.projection import project_gaussians
from ..splat.rasterizer import _np, _rows_finite
from ..splat.sh import sh_to_color
from . import kernels_baseline


@njit(parallel=True, cache=True)
def tile_rects(means2d, radii, tile_size, tiles_x, tiles_y):
    """Tile rectangle [x0, x1) x [y0, y1) of each Gaussian (gsplat's floor/ceil rule)."""
    m = means2d.shape[0]
    rects = np.zeros((m, 4), dtype=np.int64)
    for i in prange(m):
        rx = float(radii[i, 0])
        ry = float(radii[i, 1])
        if rx <= 0.0 and ry <= 0.0:
            continue
        mx = float(means2d[i, 0])
        my = float(means2d[i, 1])
        x0 = min(max(0.0, math.floor((mx - rx) / tile_size)), float(tiles_x))
        x1 = min(max(0.0, math.ceil((mx + rx) / tile_size)), float(tiles_x))
        y0 = min(max(0.0, math.floor((my - ry) / tile_size)), float(tiles_y))
        y1 = min(max(0.0, math.ceil((my + ry) / tile_size)), float(tiles_y))
        rects[i, 0] = np.int64(x0)
        rects[i, 1] = np.int64(x1)
        rects[i, 2] = np.int64(y0)
        rects[i, 3] = np.int64(y1)
    return rects


@njit(parallel=True, cache=True)
def bin_tiles(order, rects, tiles_x, tiles_y):
    """Per-tile lists of Gaussians in ``order`` (front to back): (offsets[n_tiles+1], ids[n_isect])."""
    n_tiles = tiles_x * tiles_y
    m = order.shape[0]
    counts = np.zeros((kernels.BIN_CHUNKS, n_tiles), dtype=np.int64)
    for ch in prange(kernels.BIN_CHUNKS):
        for j in range(ch * m // kernels.BIN_CHUNKS, (ch + 1) * m // kernels.BIN_CHUNKS):
            i = order[j]
            for ty in range(rects[i, 2], rects[i, 3]):
                for tx in range(rects[i, 0], rects[i, 1]):
                    counts[ch, ty * tiles_x + tx] += 1
    offsets = np.zeros(n_tiles + 1, dtype=np.int64)
    for t in range(n_tiles):
        at = offsets[t]
        for ch in range(kernels.BIN_CHUNKS):
            c = counts[ch, t]
            counts[ch, t] = at
            at += c
        offsets[t + 1] = at
    ids = np.empty(offsets[n_tiles], dtype=np.int32)
    for ch in prange(kernels.BIN_CHUNKS):
        cursor = counts[ch]
        for j in range(ch * m // kernels.BIN_CHUNKS, (ch + 1) * m // kernels.BIN_CHUNKS):
            i = order[j]
            for ty in range(rects[i, 2], rects[i, 3]):
                for tx in range(rects[i, 0], rects[i, 1]):
                    t = ty * tiles_x + tx
                    ids[cursor[t]] = i
                    cursor[t] += 1
    return offsets, ids


@njit(cache=True)
def reduce_rows(ids, r_m2d, r_conic, r_opac, r_color, g_m2d, g_conic, g_opac, g_color):
    C = r_color.shape[1]
    for j in range(ids.shape[0]):
        g = ids[j]
        g_m2d[g, 0] += r_m2d[j, 0]
        g_m2d[g, 1] += r_m2d[j, 1]
        g_conic[g, 0] += r_conic[j, 0]
        g_conic[g, 1] += r_conic[j, 1]
        g_conic[g, 2] += r_conic[j, 2]
        g_opac[g] += r_opac[j]
        for ch in range(C):
            g_color[g, ch] += r_color[j, ch]


def bin_gaussians(means2d, radii, depths, width, height, tile_size=TILE_SIZE):
    """(offsets, ids, tiles_x) of the visible Gaussians, as before."""
    tiles_x = (width + tile_size - 1) // tile_size
    tiles_y = (height + tile_size - 1) // tile_size
    m2d = np.ascontiguousarray(means2d.detach().cpu().numpy().astype(np.float64, copy=False))
    rad = np.ascontiguousarray(radii.detach().cpu().numpy().astype(np.int64, copy=False))
    order = kernels.depth_order(np.ascontiguousarray(depths.detach().cpu().numpy()))
    with KernelScope(chunk=0, items=m2d.shape[0]):
        rects = tile_rects(m2d, rad, tile_size, tiles_x, tiles_y)
        offsets, ids = bin_tiles(order, rects, tiles_x, tiles_y)
    return offsets, ids, tiles_x


class RasterizePixelsBaseline(torch.autograd.Function):
    """RasterizePixels as it was, on :mod:`.kernels_baseline`'s kernels (no groups)."""

    @staticmethod
    def forward(ctx, means2d, conics, opacities, colors, bins, width, height, threshold):
        np_dtype = np.float64 if colors.dtype == torch.float64 else np.float32
        C = colors.shape[1]
        out_color = np.zeros((height, width, C), np_dtype)
        out_T = np.ones((height, width), np.float64)
        out_inst = np.zeros((height, width, 1), np_dtype)
        out_last = np.zeros((height, width), np.int64)
        offsets, ids, tiles_x = bins
        args = (_np(means2d), _np(conics), _np(opacities), _np(colors), np.zeros(0, np.int64), 0, offsets, ids,
                int(width), int(height), tiles_x, TILE_SIZE, float(threshold))
        with KernelScope(items=ids.shape[0], serial_below=8192):
            kernels_baseline.rasterize_fwd(*args, out_color, out_T, out_inst, out_last)
        ctx.args = args
        ctx.outs = (out_color, out_T, out_inst, out_last)
        ctx.shapes = (means2d.shape[0], C, colors.dtype)
        return torch.from_numpy(out_color), torch.from_numpy((1.0 - out_T).astype(np_dtype))

    @staticmethod
    def backward(ctx, g_color, g_alpha):
        m, C, dtype = ctx.shapes
        args = ctx.args
        out_color, out_T, out_inst, out_last = ctx.outs
        H, W = out_T.shape
        np_dtype = np.float64 if dtype == torch.float64 else np.float32
        gc = np.ascontiguousarray(g_color.numpy().astype(np_dtype, copy=False))
        ga = np.ascontiguousarray(g_alpha.numpy().astype(np_dtype, copy=False))
        gi = np.zeros((H, W, 1), np_dtype)
        n_isect = args[7].shape[0]
        r_m2d = np.zeros((n_isect, 2), np_dtype)
        r_conic = np.zeros((n_isect, 3), np_dtype)
        r_opac = np.zeros(n_isect, np_dtype)
        r_color = np.zeros((n_isect, C), np_dtype)
        with KernelScope(items=n_isect, serial_below=8192):
            kernels_baseline.rasterize_bwd(*args, out_color, out_T, out_inst, out_last, gc, ga, gi,
                                           r_m2d, r_conic, r_opac, r_color)
        g_m2d = np.zeros((m, 2), np.float64)
        g_conic = np.zeros((m, 3), np.float64)
        g_opac = np.zeros(m, np.float64)
        g_col = np.zeros((m, C), np.float64)
        reduce_rows(args[7], r_m2d, r_conic, r_opac, r_color, g_m2d, g_conic, g_opac, g_col)

        def t(a):
            return torch.from_numpy(a).to(dtype=dtype)

        return t(g_m2d), t(g_conic), t(g_opac), t(g_col), None, None, None, None


def rasterize_baseline(means, quats, scales, opacities, colors, viewmat, K, width: int, height: int, *,
                       sh_degree: int | None = None, alpha_threshold: float = ALPHA_THRESHOLD, **projection):
    """``rasterize(..., backend="numba")`` as it was: ``(rgb [H,W,C], alpha [H,W,1], n_isect)``."""
    n = means.shape[0]
    is_sh = colors.dim() == 3
    if is_sh:
        deg = int(round(math.sqrt(colors.shape[1]))) - 1 if sh_degree is None else int(sh_degree)
    col_finite = _rows_finite(colors.reshape(n, -1), "numba")
    proj = project_gaussians(means, quats, scales, opacities, viewmat, K, width, height,
                             alpha_threshold=alpha_threshold, finite_mask=col_finite, backend="numba", **projection)
    vis = torch.nonzero(proj.visible, as_tuple=False).squeeze(1)
    if is_sh:
        feats = sh_to_color(deg, colors[vis], proj.rel_means[vis], backend="numba").to(colors.dtype)
    else:
        feats = colors[vis]
    depths_v = proj.depths[vis]
    feats = feats.to(means.dtype)
    m2d = proj.means2d[vis]
    bins = bin_gaussians(m2d, proj.radii[vis], depths_v, width, height)
    out, alpha = RasterizePixelsBaseline.apply(m2d, proj.conics[vis], proj.opacities[vis], feats, bins, width,
                                               height, alpha_threshold)
    return out, alpha[..., None], int(bins[1].shape[0])
