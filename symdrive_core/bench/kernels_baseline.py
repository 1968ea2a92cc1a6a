"""The pixel-outer compositing kernels the tile rasterizer used before box clipping (benchmark baseline).

Kept only so that ``scripts/bench_render.py`` can time the current kernels against them in one run and
``tests/splat/test_kernels_baseline.py`` can check that both take the same decisions. The library
renders with :mod:`symdrive_core.splat.kernels`; nothing else imports this module.

Per pixel, every Gaussian of the tile is evaluated front to back (same arguments and outputs as
:func:`symdrive_core.splat.kernels.rasterize_fwd` / ``rasterize_bwd``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..conventions import PIXEL_CENTER_OFFSET
from ..splat.kernels import ALPHA_MAX, T_STOP, sigma_limit


@njit(parallel=True, cache=True)
def rasterize_fwd(means2d, conics, opac, colors, groups, n_groups, offsets, ids, width, height, tiles_x,
                  tile_size, threshold, out_color, out_T, out_inst, out_last):
    n_tiles = offsets.shape[0] - 1
    C = colors.shape[1]
    for t in prange(n_tiles):
        ty = t // tiles_x
        tx = t - ty * tiles_x
        x0 = tx * tile_size
        y0 = ty * tile_size
        x1 = min(x0 + tile_size, width)
        y1 = min(y0 + tile_size, height)
        start = offsets[t]
        n = offsets[t + 1] - start
        lmx = np.empty(n)
        lmy = np.empty(n)
        la = np.empty(n)
        lb = np.empty(n)
        lc = np.empty(n)
        lo = np.empty(n)
        lim = np.empty(n)
        lg = np.empty(n, dtype=np.int64)
        lcol = np.empty((n, C))
        for k in range(n):
            g = ids[start + k]
            lmx[k] = means2d[g, 0]
            lmy[k] = means2d[g, 1]
            la[k] = conics[g, 0]
            lb[k] = conics[g, 1]
            lc[k] = conics[g, 2]
            lo[k] = opac[g]
            lim[k] = sigma_limit(lo[k], threshold)
            lg[k] = groups[g] if n_groups > 0 else -1
            for ch in range(C):
                lcol[k, ch] = colors[g, ch]
        acc = np.empty(C)
        for py in range(y0, y1):
            fy = py + PIXEL_CENTER_OFFSET
            for px in range(x0, x1):
                fx = px + PIXEL_CENTER_OFFSET
                T = 1.0
                for ch in range(C):
                    acc[ch] = 0.0
                last = 0
                for k in range(n):
                    dx = lmx[k] - fx
                    dy = lmy[k] - fy
                    sigma = 0.5 * (la[k] * dx * dx + lc[k] * dy * dy) + lb[k] * dx * dy
                    if sigma < 0.0 or sigma > lim[k]:
                        continue
                    alpha = min(ALPHA_MAX, lo[k] * math.exp(-sigma))
                    if alpha < threshold:
                        continue
                    next_T = T * (1.0 - alpha)
                    if next_T <= T_STOP:
                        break
                    w = alpha * T
                    for ch in range(C):
                        acc[ch] += lcol[k, ch] * w
                    if lg[k] >= 0:
                        out_inst[py, px, lg[k]] += w
                    T = next_T
                    last = k + 1
                for ch in range(C):
                    out_color[py, px, ch] = acc[ch]
                out_T[py, px] = T
                out_last[py, px] = start + last


@njit(parallel=True, cache=True)
def rasterize_bwd(means2d, conics, opac, colors, groups, n_groups, offsets, ids, width, height, tiles_x,
                  tile_size, threshold, out_color, out_T, out_inst, out_last, g_color, g_alpha, g_inst,
                  r_m2d, r_conic, r_opac, r_color):
    """Gradient rows per intersection: r_* [n_isect, ...] (summed per Gaussian by ``reduce_rows``)."""
    n_tiles = offsets.shape[0] - 1
    C = colors.shape[1]
    for t in prange(n_tiles):
        ty = t // tiles_x
        tx = t - ty * tiles_x
        x0 = tx * tile_size
        y0 = ty * tile_size
        x1 = min(x0 + tile_size, width)
        y1 = min(y0 + tile_size, height)
        start = offsets[t]
        n = offsets[t + 1] - start
        if n == 0:
            continue
        lmx = np.empty(n)
        lmy = np.empty(n)
        la = np.empty(n)
        lb = np.empty(n)
        lc = np.empty(n)
        lo = np.empty(n)
        lim = np.empty(n)
        lg = np.empty(n, dtype=np.int64)
        lcol = np.empty((n, C))
        acc = np.zeros((n, 6))  # d mean x, d mean y, d conic a, b, c, d opacity
        acol = np.zeros((n, C))
        for k in range(n):
            g = ids[start + k]
            lmx[k] = means2d[g, 0]
            lmy[k] = means2d[g, 1]
            la[k] = conics[g, 0]
            lb[k] = conics[g, 1]
            lc[k] = conics[g, 2]
            lo[k] = opac[g]
            lim[k] = sigma_limit(lo[k], threshold)
            lg[k] = groups[g] if n_groups > 0 else -1
            for ch in range(C):
                lcol[k, ch] = colors[g, ch]
        gC = np.empty(C)
        for py in range(y0, y1):
            fy = py + PIXEL_CENTER_OFFSET
            for px in range(x0, x1):
                fx = px + PIXEL_CENTER_OFFSET
                end = out_last[py, px] - start
                if end <= 0:
                    continue
                T_final = out_T[py, px]
                gA = g_alpha[py, px]
                total = 0.0  # sum over all contributions of (gC . c_j + gI_j) w_j
                for ch in range(C):
                    gC[ch] = g_color[py, px, ch]
                    total += gC[ch] * out_color[py, px, ch]
                for gi in range(n_groups):
                    total += g_inst[py, px, gi] * out_inst[py, px, gi]
                T = 1.0
                front = 0.0
                for k in range(end):
                    dx = lmx[k] - fx
                    dy = lmy[k] - fy
                    sigma = 0.5 * (la[k] * dx * dx + lc[k] * dy * dy) + lb[k] * dx * dy
                    if sigma < 0.0 or sigma > lim[k]:
                        continue
                    vis = math.exp(-sigma)
                    raw = lo[k] * vis
                    alpha = min(ALPHA_MAX, raw)
                    if alpha < threshold:
                        continue
                    w = alpha * T
                    gdot = 0.0
                    for ch in range(C):
                        gdot += gC[ch] * lcol[k, ch]
                        acol[k, ch] += w * gC[ch]
                    if lg[k] >= 0:
                        gdot += g_inst[py, px, lg[k]]
                    front += gdot * w
                    one_m = 1.0 - alpha
                    behind = total - front
                    dl_dalpha = T * gdot - behind / one_m + gA * T_final / one_m
                    T = T * one_m
                    if raw <= ALPHA_MAX:
                        acc[k, 5] += dl_dalpha * vis
                        dl_dsigma = -dl_dalpha * alpha
                        acc[k, 0] += dl_dsigma * (la[k] * dx + lb[k] * dy)
                        acc[k, 1] += dl_dsigma * (lc[k] * dy + lb[k] * dx)
                        acc[k, 2] += 0.5 * dx * dx * dl_dsigma
                        acc[k, 3] += dx * dy * dl_dsigma
                        acc[k, 4] += 0.5 * dy * dy * dl_dsigma
        for k in range(n):
            j = start + k
            r_m2d[j, 0] = acc[k, 0]
            r_m2d[j, 1] = acc[k, 1]
            r_conic[j, 0] = acc[k, 2]
            r_conic[j, 1] = acc[k, 3]
            r_conic[j, 2] = acc[k, 4]
            r_opac[j] = acc[k, 5]
            for ch in range(C):
                r_color[j, ch] = acol[k, ch]
