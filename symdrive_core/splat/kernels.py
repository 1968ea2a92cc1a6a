"""Tile-based CPU kernels (numba): binning, forward and backward of 2D Gaussian compositing.

Work is split by 16x16 tiles with ``prange`` (one tile per task, no shared writes). Per pixel,
Gaussians are composited front to back in depth order:

    sigma = a dx^2 / 2 + b dx dy + c dy^2 / 2        (dx = mean - pixel centre)
    alpha = min(0.99, o exp(-sigma))                 skipped when sigma < 0 or alpha < threshold
    stop when T (1 - alpha) <= 1e-4, that Gaussian excluded

Inside a tile the loop runs Gaussian-outer, pixel-inner over a per-pixel state (T, colour sums,
last index, done flag): each Gaussian visits only the pixels of its own box, the bounding box of
the ellipse where alpha can reach the threshold (``sigma <= sigma_limit``), rows whose pixels have
all stopped are skipped, and the tile ends when every pixel has stopped. Pixels outside the box
would have been skipped by the rule above, so the decisions (and the order of every sum) are those
of a pixel-outer loop over all Gaussians of the tile.

Arithmetic is float64 inside the kernels whatever the storage dtype, and forward and backward
evaluate alpha with the same expression, so they take the same decisions. The backward pass runs
front to back again with per-pixel running sums, gets the "behind" sums from the forward's final
values, and writes one gradient row per tile-Gaussian intersection (race free, deterministic);
rows are summed per Gaussian afterwards.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..conventions import PIXEL_CENTER_OFFSET

ALPHA_MAX = 0.99
T_STOP = 1e-4
TILE = 16
BOX_MARGIN = 1e-6  # relative and absolute widening of a Gaussian's pixel box (rounding of sigma)


@njit(cache=True, inline="always")
def sigma_limit(o, threshold):
    """A sigma above which alpha is certainly below the threshold (skips the exp; exact test follows)."""
    if threshold <= 0.0 or o <= 0.0:
        return np.inf if threshold <= 0.0 else -1.0
    return math.log(o / threshold) * (1.0 + 1e-9) + 1e-9


@njit(cache=True, inline="always")
def pixel_span(m, half, lo, hi):
    """Pixels [p0, p1) of [lo, hi) whose centre lies within ``half`` of ``m`` (all of them if unbounded)."""
    if not (half < np.inf and abs(m) < np.inf):
        return lo, hi
    first = max(float(lo), np.ceil(m - half - PIXEL_CENTER_OFFSET))
    stop = min(float(hi), np.floor(m + half - PIXEL_CENTER_OFFSET) + 1.0)
    if not first < stop:
        return lo, lo
    return int(first), int(stop)


@njit(cache=True, inline="always")
def ellipse_half_extent(a, b, c, lim):
    """Half widths (x, y) of the set ``a dx^2/2 + b dx dy + c dy^2/2 <= lim`` (inf when unbounded or unknown).

    The box is widened by ``BOX_MARGIN`` so that a pixel left out has a sigma clearly above ``lim``
    (where the rule skips it anyway); a negative ``lim`` (zero opacity) gives an empty box.
    """
    det = a * c - b * b
    if not (lim < np.inf and a > 0.0 and c > 0.0 and det > 0.0):
        return np.inf, np.inf
    if lim < 0.0:
        return -1.0, -1.0
    s = 2.0 * lim / det
    return (math.sqrt(s * c) * (1.0 + BOX_MARGIN) + BOX_MARGIN,
            math.sqrt(s * a) * (1.0 + BOX_MARGIN) + BOX_MARGIN)


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


@njit(cache=True)
def bin_tiles(order, rects, tiles_x, tiles_y):
    """Per-tile lists of Gaussians in ``order`` (front to back): (offsets[n_tiles+1], ids[n_isect])."""
    n_tiles = tiles_x * tiles_y
    counts = np.zeros(n_tiles + 1, dtype=np.int64)
    for j in range(order.shape[0]):
        i = order[j]
        for ty in range(rects[i, 2], rects[i, 3]):
            for tx in range(rects[i, 0], rects[i, 1]):
                counts[ty * tiles_x + tx + 1] += 1
    offsets = np.cumsum(counts)
    ids = np.empty(offsets[n_tiles], dtype=np.int32)
    cursor = offsets[:n_tiles].copy()
    for j in range(order.shape[0]):
        i = order[j]
        for ty in range(rects[i, 2], rects[i, 3]):
            for tx in range(rects[i, 0], rects[i, 1]):
                t = ty * tiles_x + tx
                ids[cursor[t]] = i
                cursor[t] += 1
    return offsets, ids


@njit(cache=True, inline="always")
def _load_tile(means2d, conics, opac, colors, groups, n_groups, ids, start, n, threshold):
    """Tile-local float64 copies of the tile's Gaussians, with their sigma limit and box half widths."""
    C = colors.shape[1]
    geo = np.empty((n, 8))  # mean x, mean y, conic a, b, c, opacity, half width x, half width y
    lim = np.empty(n)
    lg = np.empty(n, dtype=np.int64)
    lcol = np.empty((n, C))
    for k in range(n):
        g = ids[start + k]
        geo[k, 0] = means2d[g, 0]
        geo[k, 1] = means2d[g, 1]
        geo[k, 2] = conics[g, 0]
        geo[k, 3] = conics[g, 1]
        geo[k, 4] = conics[g, 2]
        geo[k, 5] = opac[g]
        lim[k] = sigma_limit(geo[k, 5], threshold)
        geo[k, 6], geo[k, 7] = ellipse_half_extent(geo[k, 2], geo[k, 3], geo[k, 4], lim[k])
        lg[k] = groups[g] if n_groups > 0 else -1
        for ch in range(C):
            lcol[k, ch] = colors[g, ch]
    return geo, lim, lg, lcol


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
        geo, lim, lg, lcol = _load_tile(means2d, conics, opac, colors, groups, n_groups, ids, start, n,
                                        threshold)
        npx = tile_size * tile_size
        T = np.ones(npx)
        acc = np.zeros((npx, C))
        last = np.zeros(npx, dtype=np.int64)
        done = np.zeros(npx, dtype=np.bool_)
        row_live = np.full(tile_size, x1 - x0, dtype=np.int64)
        live = (x1 - x0) * (y1 - y0)
        for k in range(n):
            if live == 0:
                break
            mx = geo[k, 0]
            my = geo[k, 1]
            a = geo[k, 2]
            b = geo[k, 3]
            c = geo[k, 4]
            o = geo[k, 5]
            lk = lim[k]
            grp = lg[k]
            px0, px1 = pixel_span(mx, geo[k, 6], x0, x1)
            py0, py1 = pixel_span(my, geo[k, 7], y0, y1)
            for py in range(py0, py1):
                r = py - y0
                if row_live[r] == 0:
                    continue
                dy = my - (py + PIXEL_CENTER_OFFSET)
                base = r * tile_size - x0
                for px in range(px0, px1):
                    p = base + px
                    if done[p]:
                        continue
                    dx = mx - (px + PIXEL_CENTER_OFFSET)
                    sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy
                    if sigma < 0.0 or sigma > lk:
                        continue
                    alpha = min(ALPHA_MAX, o * math.exp(-sigma))
                    if alpha < threshold:
                        continue
                    Tp = T[p]
                    next_T = Tp * (1.0 - alpha)
                    if next_T <= T_STOP:
                        done[p] = True
                        row_live[r] -= 1
                        live -= 1
                        continue
                    w = alpha * Tp
                    for ch in range(C):
                        acc[p, ch] += lcol[k, ch] * w
                    if grp >= 0:
                        out_inst[py, px, grp] += w
                    T[p] = next_T
                    last[p] = k + 1
        for py in range(y0, y1):
            base = (py - y0) * tile_size - x0
            for px in range(x0, x1):
                p = base + px
                for ch in range(C):
                    out_color[py, px, ch] = acc[p, ch]
                out_T[py, px] = T[p]
                out_last[py, px] = start + last[p]


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
        npx = tile_size * tile_size
        end = np.zeros(npx, dtype=np.int64)  # Gaussians [0, end) of the tile reached the pixel
        row_end = np.zeros(tile_size, dtype=np.int64)
        T = np.ones(npx)
        front = np.zeros(npx)  # sum over the contributions so far of (gC . c_j + gI_j) w_j
        total = np.zeros(npx)  # the same sum over all contributions
        T_final = np.ones(npx)
        gA = np.zeros(npx)
        gC = np.zeros((npx, C))
        n_end = 0
        for py in range(y0, y1):
            r = py - y0
            base = r * tile_size - x0
            for px in range(x0, x1):
                p = base + px
                e = out_last[py, px] - start
                end[p] = e
                row_end[r] = max(row_end[r], e)
                n_end = max(n_end, e)
                T_final[p] = out_T[py, px]
                gA[p] = g_alpha[py, px]
                s = 0.0
                for ch in range(C):
                    gC[p, ch] = g_color[py, px, ch]
                    s += gC[p, ch] * out_color[py, px, ch]
                for gi in range(n_groups):
                    s += g_inst[py, px, gi] * out_inst[py, px, gi]
                total[p] = s
        if n_end <= 0:
            continue
        geo, lim, lg, lcol = _load_tile(means2d, conics, opac, colors, groups, n_groups, ids, start, n_end,
                                        threshold)
        acol = np.zeros(C)
        for k in range(n_end):
            mx = geo[k, 0]
            my = geo[k, 1]
            a = geo[k, 2]
            b = geo[k, 3]
            c = geo[k, 4]
            o = geo[k, 5]
            lk = lim[k]
            grp = lg[k]
            px0, px1 = pixel_span(mx, geo[k, 6], x0, x1)
            py0, py1 = pixel_span(my, geo[k, 7], y0, y1)
            d_mx = 0.0
            d_my = 0.0
            d_a = 0.0
            d_b = 0.0
            d_c = 0.0
            d_o = 0.0
            for ch in range(C):
                acol[ch] = 0.0
            for py in range(py0, py1):
                r = py - y0
                if k >= row_end[r]:
                    continue
                dy = my - (py + PIXEL_CENTER_OFFSET)
                base = r * tile_size - x0
                for px in range(px0, px1):
                    p = base + px
                    if k >= end[p]:
                        continue
                    dx = mx - (px + PIXEL_CENTER_OFFSET)
                    sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy
                    if sigma < 0.0 or sigma > lk:
                        continue
                    vis = math.exp(-sigma)
                    raw = o * vis
                    alpha = min(ALPHA_MAX, raw)
                    if alpha < threshold:
                        continue
                    Tp = T[p]
                    w = alpha * Tp
                    gdot = 0.0
                    for ch in range(C):
                        gdot += gC[p, ch] * lcol[k, ch]
                        acol[ch] += w * gC[p, ch]
                    if grp >= 0:
                        gdot += g_inst[py, px, grp]
                    fr = front[p] + gdot * w
                    front[p] = fr
                    one_m = 1.0 - alpha
                    behind = total[p] - fr
                    dl_dalpha = Tp * gdot - behind / one_m + gA[p] * T_final[p] / one_m
                    T[p] = Tp * one_m
                    if raw <= ALPHA_MAX:
                        d_o += dl_dalpha * vis
                        dl_dsigma = -dl_dalpha * alpha
                        d_mx += dl_dsigma * (a * dx + b * dy)
                        d_my += dl_dsigma * (c * dy + b * dx)
                        d_a += 0.5 * dx * dx * dl_dsigma
                        d_b += dx * dy * dl_dsigma
                        d_c += 0.5 * dy * dy * dl_dsigma
            j = start + k
            r_m2d[j, 0] = d_mx
            r_m2d[j, 1] = d_my
            r_conic[j, 0] = d_a
            r_conic[j, 1] = d_b
            r_conic[j, 2] = d_c
            r_opac[j] = d_o
            for ch in range(C):
                r_color[j, ch] = acol[ch]


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
