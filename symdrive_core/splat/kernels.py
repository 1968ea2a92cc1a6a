"""Tile-based CPU kernels (numba): binning, forward and backward of 2D Gaussian compositing.

Work is split by 16x16 tiles with ``prange`` (one tile per task, no shared writes; taken in
strips of ``TILE_STRIP`` tile rows, column by column, so that a Gaussian's tiles run close
together). Per pixel, Gaussians are composited front to back in depth order:

    sigma = a dx^2 / 2 + b dx dy + c dy^2 / 2        (dx = mean - pixel centre)
    alpha = min(0.99, o exp(-sigma))                 skipped when sigma < 0 or alpha < threshold
    stop when T (1 - alpha) <= 1e-4, that Gaussian excluded

Inside a tile the loop runs Gaussian-outer, pixel-inner over a per-pixel state (T, colour sums,
last index, done flag): each Gaussian visits only the rows of its own box, the bounding box of the
ellipse where alpha can reach the threshold (``sigma <= sigma_limit``); rows whose pixels have all
stopped are skipped, and the tile ends when every pixel has stopped. A row is one branch-free loop
over the tile's 16 pixels (selects instead of ``if``, unsigned indices so numba emits no
negative-index wraparound, the state in one buffer at constant offsets so LLVM needs no aliasing
checks, and ``exp_neg`` instead of libm's scalar ``exp``), which LLVM turns into a few vector
instructions per row; a Gaussian whose box spans at most a quarter or half of a tile row takes only
the ``QUARTER`` or ``HALF`` pixels that hold it (:func:`_row_window`; forward and backward alike),
one or two AVX2 vectors of float64 instead of four. Pixels outside the
box would have been skipped by the rule above, so the decisions are those of a pixel-outer loop over
all Gaussians of the tile; sums differ from that order only by rounding. Each Gaussian is packed
once per kernel call into one float64 record (geometry, sigma limit, box half widths, group,
colour; in a scratch buffer the caller keeps), read per intersection in chunks.

A tile list may leave out a Gaussian where it would be skipped at every pixel of the tile
(:func:`ellipse_rects`: tiles outside its box, or that its ellipse, slightly widened, does not reach):
the same decisions with fewer tile-Gaussian pairs.

Arithmetic is float64 inside the kernels whatever the storage dtype, and forward and backward
evaluate alpha with the same expression, so they take the same decisions. The backward pass runs
front to back again with per-pixel running sums, gets the "behind" sums from the forward's final
values, and writes one gradient row per tile-Gaussian intersection (race free, deterministic);
rows are summed per Gaussian afterwards.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, prange, types, uint64
from numba.extending import intrinsic

from ..conventions import PIXEL_CENTER_OFFSET
from .compile_notice import announce_compiles
from .constants import ALPHA_MAX, T_STOP
from .constants import TILE_SIZE as TILE

announce_compiles()

NPX = TILE * TILE
HALF = TILE // 2  # a narrow Gaussian's rows are evaluated over HALF or QUARTER pixels
QUARTER = TILE // 4
# per-pixel state of a tile, slots of NPX values: forward (see rasterize_fwd) and backward (rasterize_bwd)
F_T, F_DONE, F_LAST, F_W, F_ACC = range(5)
B_T, B_FRONT, B_TOTAL, B_TFIN, B_GA, B_END, B_EXTRA, B_W, B_DSIG, B_DOP, B_GC = range(11)
FUSED_CHANNELS = 4  # colour channels summed inside the forward's row loop (RGB + depth); more take extra passes
LOAD_CHUNK = 32  # records a forward tile reads at a time
TILE_STRIP = 4  # tile rows the kernels walk column by column (see _tile_at)
PACK_PIECES = 64  # pieces of the Gaussians packed in parallel
BIN_CHUNKS = 32  # pieces of the depth order binned in parallel
RADIX_BITS = 16  # bits per pass of the depth sort (2 passes for float32 depths)
BOX_MARGIN = 1e-6  # relative and absolute widening of a Gaussian's pixel box (rounding of sigma)
CULL_MARGIN = 4e-6  # relative and absolute widening of the ellipse that decides a Gaussian's tiles
CULL_COND = 1e6  # ellipses with a c / det above this (needles) keep every tile of their rectangle
CULL_SIDE = 8  # rectangles up to this many tiles a side are cut to their ellipse (a 64-bit mask)
EVERY_TILE = np.uint64(0xFFFFFFFFFFFFFFFF)
LN2_HI = 6.93147180369123816490e-01  # ln 2 split for an exact k ln 2 (fdlibm's constants)
LN2_LO = 1.90821492927058770002e-10
INV_LN2 = 1.44269504088896338700e+00


@njit(cache=True, inline="always")
def sigma_limit(o, threshold):
    """A sigma above which alpha is certainly below the threshold (skips the exp; exact test follows)."""
    if threshold <= 0.0 or o <= 0.0:
        return np.inf if threshold <= 0.0 else -1.0
    return math.log(o / threshold) * (1.0 + 1e-9) + 1e-9


@intrinsic
def _bits_to_float64(typingctx, bits):
    """The float64 whose IEEE bit pattern is the int64 ``bits``."""
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())
    return types.float64(types.int64), codegen


@njit(cache=True, inline="always")
def pow2_neg(k):
    """2^-k for k = 0 .. 1074 (subnormals included), exactly, from its bit pattern: a few integer
    operations that vectorise, where a table read would be a gather."""
    normal = (1023 - min(k, 1022)) << 52  # biased exponent 1023 - k
    subnormal = 1 << max(min(1074 - k, 62), 0)  # k > 1022: the single mantissa bit 1074 - k
    return _bits_to_float64(normal if k <= 1022 else subnormal)


@njit(cache=True, fastmath={"contract"})
def exp_neg(s):
    """exp(-s) within 2 ulp of ``math.exp`` (0 < exp(-s) <= 1, s clamped to [0, 744]).

    Arithmetic, a floor and a table read only, so a pixel loop that calls it vectorises (libm's
    ``exp`` is a scalar call that keeps the loop scalar). Range reduction s = k ln 2 - r, |r| <= ln2/2,
    then Taylor to degree 13 (truncation below 2e-17) by fused multiply-adds (``contract``, in this
    function only: the callers' decisions keep plain rounding), times 2^-k built from its bits.
    """
    x = min(0.0, max(-s, -744.0))
    kf = math.floor(x * INV_LN2 + 0.5)
    r = (x - kf * LN2_HI) - kf * LN2_LO
    q = 1.0 / 6227020800.0
    q = q * r + 1.0 / 479001600.0
    q = q * r + 1.0 / 39916800.0
    q = q * r + 1.0 / 3628800.0
    q = q * r + 1.0 / 362880.0
    q = q * r + 1.0 / 40320.0
    q = q * r + 1.0 / 5040.0
    q = q * r + 1.0 / 720.0
    q = q * r + 1.0 / 120.0
    q = q * r + 1.0 / 24.0
    q = q * r + 1.0 / 6.0
    q = q * r + 0.5
    q = q * r + 1.0
    q = q * r + 1.0
    return q * pow2_neg(int(-kf))


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


@njit(cache=True, inline="always")
def _tile_range(m, r, tile_size, n_tiles):
    """Tiles [t0, t1) that the box ``m +- r`` (pixels) touches, gsplat's floor/ceil rule, within [0, n_tiles]."""
    return (int(min(max(0.0, math.floor((m - r) / tile_size)), float(n_tiles))),
            int(min(max(0.0, math.ceil((m + r) / tile_size)), float(n_tiles))))


@njit(parallel=True, cache=True)
def tile_rects(means2d, radii, order, tile_size, tiles_x, tiles_y):
    """Tile rectangle [x0, x1) x [y0, y1) (gsplat's floor/ceil rule) of Gaussian ``order[j]`` in row j.

    In depth order, so that binning reads the rectangles as a stream instead of one random read per
    Gaussian and pass; int32, half the bytes of int64. Computed in index order (the inputs read as
    streams), then gathered: one random read per Gaussian instead of two.
    """
    n = means2d.shape[0]
    own = np.empty((n, 4), dtype=np.int32)
    for i in prange(n):
        rx = float(radii[i, 0])
        ry = float(radii[i, 1])
        x0, x1, y0, y1 = 0, 0, 0, 0
        if rx > 0.0 or ry > 0.0:
            x0, x1 = _tile_range(float(means2d[i, 0]), rx, tile_size, tiles_x)
            y0, y1 = _tile_range(float(means2d[i, 1]), ry, tile_size, tiles_y)
        own[i, 0] = x0
        own[i, 1] = x1
        own[i, 2] = y0
        own[i, 3] = y1
    m = order.shape[0]
    rects = np.empty((m, 4), dtype=np.int32)
    for j in prange(m):
        i = order[j]
        for f in range(4):
            rects[j, f] = own[i, f]
    return rects


@njit(cache=True, inline="always")
def _box_tiles(m, half, size, t0, t1):
    """Tiles of [t0, t1) holding a pixel of :func:`pixel_span`'s box ``m +- half`` (image ``size``
    pixels): those where the kernels' span is not empty."""
    if not (half < np.inf and abs(m) < np.inf):
        return t0, t1
    first = math.ceil(m - half - PIXEL_CENTER_OFFSET)  # the box's pixels [first, stop), before clipping
    stop = math.floor(m + half - PIXEL_CENTER_OFFSET) + 1.0
    if not (first < stop and first < size):
        return t0, t0
    u0 = max(float(t0), math.floor(first / TILE))
    u1 = min(float(t1), math.ceil(stop / TILE))
    if not u0 < u1:
        return t0, t0
    return int(u0), int(u1)


@njit(cache=True, inline="always")
def _band_span(mx, my, b, det, a2lw, inv_a, t, yc0, yc1):
    """Pixel-centre x interval [lo, hi] where the ellipse ``a dx^2/2 + b dx dy + c dy^2/2 <= lw`` has a
    point with pixel-centre y in [yc0, yc1] (lo > hi when there is none); ``a2lw = 2 a lw``,
    ``inv_a = 1 / a``, ``t = b hx / c`` (its extreme x points are (hx, -t) and (-hx, t) in (dx, dy)).

    The right end of the ellipse's chord at dy, ``(sqrt(2 a lw - det dy^2) - b dy) / a``, is largest at
    dy = -t and falls off on either side (the left end mirrors it at t), so the band's extremes lie at
    those dy clamped into the band.
    """
    dlo = my - yc1  # dy = mean - pixel centre over the band
    dhi = my - yc0
    dr = min(max(-t, dlo), dhi)
    dl = min(max(t, dlo), dhi)
    disc_r = a2lw - det * dr * dr
    disc_l = a2lw - det * dl * dl
    if disc_r < 0.0 or disc_l < 0.0:
        return np.inf, -np.inf
    return mx - (math.sqrt(disc_r) - b * dr) * inv_a, mx + (math.sqrt(disc_l) + b * dl) * inv_a  # x = mx - dx


@njit(cache=True, inline="always")
def _tile_mask(mx, my, a, b, c, lim, x0, x1, y0, y1):
    """Bit (ty - y0) * CULL_SIDE + (tx - x0) per tile of the rectangle that the ellipse reaches.

    The ellipse is the kernels' ``sigma <= lim`` widened by ``CULL_MARGIN`` (relative and absolute, in
    sigma and in the x extent): a pixel outside it has a sigma well above ``lim`` whatever the
    rounding, so the kernels would skip it. Every bit is set for ellipses that are unbounded or
    needle-like (``a c > CULL_COND det``, where the rounding of sigma grows) and for non-finite values.
    """
    det = a * c - b * b
    if not (lim >= 0.0 and lim < np.inf and a > 0.0 and c > 0.0 and det > 0.0 and a < np.inf and c < np.inf
            and abs(mx) < np.inf and abs(my) < np.inf and a * c <= CULL_COND * det):
        return EVERY_TILE
    lw = lim * (1.0 + CULL_MARGIN) + CULL_MARGIN
    hx = math.sqrt(2.0 * lw * c / det)
    pad = CULL_MARGIN * hx + CULL_MARGIN  # covers the rounding of the chord's ends
    a2lw = 2.0 * a * lw
    inv_a = 1.0 / a
    t = b * hx / c
    mask = np.uint64(0)
    for ty in range(y0, y1):
        lo, hi = _band_span(mx, my, b, det, a2lw, inv_a, t, ty * TILE + PIXEL_CENTER_OFFSET,
                            ty * TILE + TILE - 1 + PIXEL_CENTER_OFFSET)
        t0 = max(float(x0), math.ceil((lo - pad - (TILE - 1 + PIXEL_CENTER_OFFSET)) / TILE))
        t1 = min(float(x1), math.floor((hi + pad - PIXEL_CENTER_OFFSET) / TILE) + 1.0)
        if t0 < t1:  # (false when the band misses the ellipse: lo > hi)
            row = (np.uint64(1) << np.uint64(int(t1) - x0)) - np.uint64(1)
            row &= ~((np.uint64(1) << np.uint64(int(t0) - x0)) - np.uint64(1))
            mask |= row << np.uint64((ty - y0) * CULL_SIDE)
    return mask


@njit(parallel=True, cache=True)
def ellipse_rects(means2d, radii, conics, opac, order, threshold, width, height, tile_size, tiles_x, tiles_y):
    """:func:`tile_rects` cut to the tiles where the kernels can use the Gaussian: ``(rects, masks)``
    in depth order (row j: Gaussian ``order[j]``).

    The rectangle shrinks to the tiles that hold a pixel of the kernels' own box (``pixel_span`` of
    ``ellipse_half_extent``, the same values: tiles outside it are skipped there at once), and for
    rectangles of 2 to ``CULL_SIDE`` tiles a side ``masks[j]`` keeps only the tiles that the ellipse
    reaches (:func:`_tile_mask`; every bit set otherwise). Computed in index order (the inputs read
    as streams), then gathered into depth order in one random read per Gaussian.
    """
    m = means2d.shape[0]
    snug = np.zeros((m, 4), dtype=np.int32)
    cut = np.empty(m, dtype=np.uint64)
    for i in prange(m):
        cut[i] = EVERY_TILE
        rx = float(radii[i, 0])
        ry = float(radii[i, 1])
        if rx <= 0.0 and ry <= 0.0:
            continue
        mx = float(means2d[i, 0])
        my = float(means2d[i, 1])
        a = float(conics[i, 0])
        b = float(conics[i, 1])
        c = float(conics[i, 2])
        lim = sigma_limit(float(opac[i]), threshold)
        hx, hy = ellipse_half_extent(a, b, c, lim)
        t0, t1 = _tile_range(mx, rx, tile_size, tiles_x)
        x0, x1 = _box_tiles(mx, hx, width, t0, t1)
        t0, t1 = _tile_range(my, ry, tile_size, tiles_y)
        y0, y1 = _box_tiles(my, hy, height, t0, t1)
        if x0 == x1 or y0 == y1:
            continue
        snug[i, 0] = x0
        snug[i, 1] = x1
        snug[i, 2] = y0
        snug[i, 3] = y1
        if x1 - x0 >= 2 and y1 - y0 >= 2 and x1 - x0 <= CULL_SIDE and y1 - y0 <= CULL_SIDE:
            cut[i] = _tile_mask(mx, my, a, b, c, lim, x0, x1, y0, y1)
    rects = np.empty((order.shape[0], 4), dtype=np.int32)
    masks = np.empty(order.shape[0], dtype=np.uint64)
    for j in prange(order.shape[0]):
        i = order[j]
        for f in range(4):
            rects[j, f] = snug[i, f]
        masks[j] = cut[i]
    return rects, masks


@njit(cache=True, inline="always")
def _tile_kept(masks, j, tx, ty, x0, x1, y0, y1):
    """Whether Gaussian j's list gets tile (tx, ty) of its rectangle (see :func:`ellipse_rects`)."""
    if masks.shape[0] == 0 or x1 - x0 > CULL_SIDE or y1 - y0 > CULL_SIDE:
        return True
    return (masks[j] >> np.uint64((ty - y0) * CULL_SIDE + tx - x0)) & np.uint64(1) != 0


def depth_order(depths: np.ndarray) -> np.ndarray:
    """Indices sorting ``depths`` (float32/float64) ascending, ties by index: ``np.argsort(kind="stable")``.

    An LSD radix sort of the IEEE bit patterns (sign folded so that the unsigned order is the float
    order), ``RADIX_BITS`` per pass: a few streaming passes instead of a comparison sort.
    """
    depths = np.ascontiguousarray(depths) + depths.dtype.type(0.0)  # -0.0 -> +0.0 (equal, ties by index)
    n_bits = depths.dtype.itemsize * 8
    bits = depths.view(np.uint32 if n_bits == 32 else np.uint64).astype(np.uint64)
    sign = np.uint64(1) << np.uint64(n_bits - 1)
    full = np.uint64((1 << n_bits) - 1)
    codes = np.where(bits & sign, bits ^ full, bits | sign)
    return _radix_order(codes, n_bits)


@njit(cache=True)
def _radix_order(codes, n_bits):
    n = codes.shape[0]
    order = np.arange(n, dtype=np.int64)
    tmp = np.empty(n, dtype=np.int64)
    n_buckets = 1 << RADIX_BITS
    mask = np.uint64(n_buckets - 1)
    for shift in range(0, n_bits, RADIX_BITS):
        sh = np.uint64(shift)
        counts = np.zeros(n_buckets + 1, dtype=np.int64)
        for i in range(n):
            counts[((codes[i] >> sh) & mask) + np.uint64(1)] += 1
        if counts.max() == n:
            continue  # every key has the same digit here: the pass would not move anything
        for d in range(n_buckets):
            counts[d + 1] += counts[d]
        for j in range(n):
            i = order[j]
            d = (codes[i] >> sh) & mask
            tmp[counts[d]] = i
            counts[d] += 1
        order, tmp = tmp, order
    return order


@njit(parallel=True, cache=True)
def bin_tiles(order, rects, tiles_x, tiles_y, masks, with_rows=True):
    """Per-tile lists of Gaussians in ``order`` (front to back) and each Gaussian's list positions.

    ``rects[j]`` is Gaussian ``order[j]``'s tile rectangle (:func:`tile_rects`, :func:`ellipse_rects`) and
    ``masks[j]``, when ``masks`` has rows, the tiles of it that get an entry (:func:`ellipse_rects`). Returns
    ``(offsets[n_tiles+1], ids[n_isect], row_start[m+1], rows[n_isect])``: tile t's list is
    ``ids[offsets[t]:offsets[t+1]]``; Gaussian g's list positions are ``rows[row_start[g]:row_start[g+1]]``,
    increasing (its tiles are visited row by row), so :func:`reduce_rows` sums per Gaussian in
    parallel in the order of one serial pass over the lists.
    ``order`` is cut into ``BIN_CHUNKS`` pieces counted and written in parallel; within a tile the
    pieces follow each other in order, so the lists are those of one pass in ``order``.
    ``with_rows`` False (a frame that needs no gradients) leaves ``row_start`` and ``rows`` empty.
    """
    n_tiles = tiles_x * tiles_y
    m = order.shape[0]
    counts = np.zeros((BIN_CHUNKS, n_tiles), dtype=np.int64)
    per_gaussian = np.zeros(m + 1 if with_rows else 0, dtype=np.int64)
    for ch in prange(BIN_CHUNKS):
        for j in range(ch * m // BIN_CHUNKS, (ch + 1) * m // BIN_CHUNKS):
            x0, x1, y0, y1 = rects[j, 0], rects[j, 1], rects[j, 2], rects[j, 3]
            total = 0
            for ty in range(y0, y1):
                for tx in range(x0, x1):
                    if _tile_kept(masks, j, tx, ty, x0, x1, y0, y1):
                        counts[ch, ty * tiles_x + tx] += 1
                        total += 1
            if with_rows:
                per_gaussian[order[j] + 1] = total
    offsets = np.zeros(n_tiles + 1, dtype=np.int64)
    for t in range(n_tiles):  # counts become each piece's first slot in the tile's list
        at = offsets[t]
        for ch in range(BIN_CHUNKS):
            c = counts[ch, t]
            counts[ch, t] = at
            at += c
        offsets[t + 1] = at
    row_start = np.cumsum(per_gaussian)
    ids = np.empty(offsets[n_tiles], dtype=np.int32)
    rows = np.empty(offsets[n_tiles] if with_rows else 0, dtype=np.int64)
    for ch in prange(BIN_CHUNKS):
        cursor = counts[ch]
        for j in range(ch * m // BIN_CHUNKS, (ch + 1) * m // BIN_CHUNKS):
            i = order[j]
            at = row_start[i] if with_rows else 0
            x0, x1, y0, y1 = rects[j, 0], rects[j, 1], rects[j, 2], rects[j, 3]
            for ty in range(y0, y1):
                for tx in range(x0, x1):
                    if not _tile_kept(masks, j, tx, ty, x0, x1, y0, y1):
                        continue
                    t = ty * tiles_x + tx
                    ids[cursor[t]] = i
                    if with_rows:
                        rows[at] = cursor[t]
                        at += 1
                    cursor[t] += 1
    return offsets, ids, row_start, rows


@njit(parallel=True, cache=True)
def take_rows(src, rows, out):
    """out[j] = src[rows[j]] for 2D arrays: the visible Gaussians' rows in one parallel pass."""
    for j in prange(rows.shape[0]):
        i = rows[j]
        for f in range(src.shape[1]):
            out[j, f] = src[i, f]


@njit(parallel=True, cache=True)
def put_rows(src, pos, out):
    """out[i] = src[pos[i]], zeros where pos[i] < 0: take_rows' gradient, every row of ``out`` written once."""
    for i in prange(out.shape[0]):
        j = pos[i]
        for f in range(out.shape[1]):
            out[i, f] = src[j, f] if j >= 0 else 0.0


# one float64 record per Gaussian, read once per tile-Gaussian intersection (one contiguous read
# instead of four scattered ones, and the limit and box computed once per Gaussian)
R_MX, R_MY, R_A, R_B, R_C, R_O, R_HX, R_HY, R_LIM, R_GROUP, R_COLOR = range(11)


@njit(cache=True, inline="always")
def _pack_records(means2d, conics, opac, colors, groups, n_groups, threshold, rec):
    C = colors.shape[1]
    m = means2d.shape[0]
    if rec.shape[0] != m or rec.shape[1] != R_COLOR + C:
        raise ValueError("the record buffer must be [n Gaussians, R_COLOR + channels]")
    # in PACK_PIECES contiguous pieces: the kernels' parallel chunk is sized for tiles, and handing
    # out a few Gaussians at a time would cost more than packing them
    for piece in prange(PACK_PIECES):
        for g in range(piece * m // PACK_PIECES, (piece + 1) * m // PACK_PIECES):
            rec[g, R_MX] = means2d[g, 0]
            rec[g, R_MY] = means2d[g, 1]
            rec[g, R_A] = conics[g, 0]
            rec[g, R_B] = conics[g, 1]
            rec[g, R_C] = conics[g, 2]
            rec[g, R_O] = opac[g]
            lim = sigma_limit(rec[g, R_O], threshold)
            rec[g, R_LIM] = lim
            rec[g, R_HX], rec[g, R_HY] = ellipse_half_extent(rec[g, R_A], rec[g, R_B], rec[g, R_C], lim)
            rec[g, R_GROUP] = groups[g] if n_groups > 0 else -1
            for ch in range(C):
                rec[g, R_COLOR + ch] = colors[g, ch]
    return rec


@njit(cache=True, inline="always")
def _tile_at(i, tiles_x, tiles_y):
    """Tile (index, x, y) taken i-th: strips of ``TILE_STRIP`` tile rows, each column by column, so
    that the tiles of a Gaussian (and its record, read from memory) come close together."""
    strip = i // (TILE_STRIP * tiles_x)
    rows = min(TILE_STRIP, tiles_y - strip * TILE_STRIP)
    within = i - strip * TILE_STRIP * tiles_x
    tx = within // rows
    ty = strip * TILE_STRIP + within - tx * rows
    return ty * tiles_x + tx, tx, ty


@njit(cache=True, inline="always")
def _copy_records(rec, ids, start, k0, k1, loc):
    """Rows [k0, k1) of the tile's records into ``loc`` (a tight loop keeps many reads in flight)."""
    for k in range(k0, k1):
        g = ids[start + k]
        for f in range(rec.shape[1]):
            loc[k, f] = rec[g, f]


@njit(cache=True, inline="always")
def _fwd_row(st, p0, xw, width, mx, dy, a, b, c, o, lk, threshold, kk, c0, c1, c2, c3):
    """The forward's update of ``width`` pixels of a tile row, state slots from ``p0``, image columns
    from ``xw``: branch free with unsigned indices, one fixed-width vector loop (``width`` is a
    constant at each call). Returns how many of the pixels stopped and how many kept the Gaussian."""
    o_done = uint64(F_DONE * NPX)
    o_last = uint64(F_LAST * NPX)
    o_w = uint64(F_W * NPX)
    o_acc = uint64(F_ACC * NPX)
    stops = 0
    kept = 0
    for i in range(width):
        p = uint64(p0 + i)
        dx = mx - (xw + i + PIXEL_CENTER_OFFSET)
        sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy
        alpha = min(ALPHA_MAX, o * exp_neg(sigma))
        Tp = st[p]  # F_T / B_T: slot 0
        next_T = Tp * (1.0 - alpha)
        hit = (st[o_done + p] == 0.0) & (sigma >= 0.0) & (sigma <= lk) & (alpha >= threshold)
        stop = hit & (next_T <= T_STOP)
        keep = hit & (next_T > T_STOP)
        wv = alpha * Tp if keep else 0.0
        st[o_w + p] = wv
        st[p] = next_T if keep else Tp
        st[o_last + p] = kk if keep else st[o_last + p]
        st[o_done + p] = 1.0 if stop else st[o_done + p]
        st[o_acc + p] += c0 * wv
        st[o_acc + uint64(NPX) + p] += c1 * wv
        st[o_acc + uint64(2 * NPX) + p] += c2 * wv
        st[o_acc + uint64(3 * NPX) + p] += c3 * wv
        stops += stop
        kept += keep
    return stops, kept


@njit(cache=True, inline="always")
def _row_window(px0, px1, x0):
    """(first tile column, width) of the row window a box's pixels [px0, px1) are evaluated over:
    ``QUARTER``, ``HALF`` or ``TILE`` pixels, the narrowest that holds them (each call site of the
    row functions has its width as a constant, so each is one fixed-width vector loop)."""
    span = px1 - px0
    wn = QUARTER if span <= QUARTER else (HALF if span <= HALF else TILE)
    return min(px0 - x0, TILE - wn), wn


@njit(cache=True, inline="always")
def _unpack_record(g, x0, x1, y0, y1):
    """A packed record's 2D mean, conic, opacity, sigma limit and group, and its pixel span in the tile
    [x0, x1) x [y0, y1) (empty when px0 == px1): forward and backward read a record the same way."""
    mx = g[R_MX]
    my = g[R_MY]
    px0, px1 = pixel_span(mx, g[R_HX], x0, x1)
    py0, py1 = pixel_span(my, g[R_HY], y0, y1)
    return mx, my, g[R_A], g[R_B], g[R_C], g[R_O], g[R_LIM], int(g[R_GROUP]), px0, px1, py0, py1


@njit(parallel=True, cache=True)
def rasterize_fwd(means2d, conics, opac, colors, groups, n_groups, offsets, ids, width, height, tiles_x,
                  tile_size, threshold, out_color, out_T, out_inst, out_last, rec):
    """Forward compositing into out_* (colour sums, final T, instance weights, last list position + 1
    per pixel). ``rec`` [m, R_COLOR + C] float64 is scratch for the packed records (its contents
    are overwritten): a buffer the caller keeps between frames spares the fresh pages of a new one.
    """
    if tile_size != TILE:
        raise ValueError("the compositing kernels need tiles of TILE pixels")
    _pack_records(means2d, conics, opac, colors, groups, n_groups, threshold, rec)
    n_tiles = offsets.shape[0] - 1
    C = colors.shape[1]
    for i_tile in prange(n_tiles):
        t, tx, ty = _tile_at(i_tile, tiles_x, n_tiles // tiles_x)
        x0 = tx * TILE
        y0 = ty * TILE
        x1 = min(x0 + TILE, width)
        y1 = min(y0 + TILE, height)
        start = offsets[t]
        n = offsets[t + 1] - start
        # per-pixel state in one buffer at constant offsets from the pixel, so that the row loop needs
        # no aliasing checks: T, done (0/1), last index + 1, weight alpha T, then the colour sums
        o_w = uint64(F_W * NPX)
        o_acc = uint64(F_ACC * NPX)
        st = np.zeros((F_ACC + max(C, FUSED_CHANNELS)) * NPX)
        st[F_T * NPX:(F_T + 1) * NPX] = 1.0
        st[F_DONE * NPX:(F_DONE + 1) * NPX] = 1.0  # pixels outside the image stay done
        for r in range(y1 - y0):
            for i in range(x1 - x0):
                st[F_DONE * NPX + r * TILE + i] = 0.0
        row_live = np.zeros(TILE, dtype=np.int64)
        row_live[:y1 - y0] = x1 - x0
        live = (x1 - x0) * (y1 - y0)
        loc = np.empty((n, rec.shape[1]))
        col = np.zeros(max(C, FUSED_CHANNELS))
        loaded = 0  # read in chunks: a tile whose pixels all stop early never reads the rest of its list
        for k in range(n):
            if live == 0:
                break
            if k == loaded:
                loaded = min(n, loaded + LOAD_CHUNK)
                _copy_records(rec, ids, start, k, loaded, loc)
            g = loc[k]
            mx, my, a, b, c, o, lk, grp, px0, px1, py0, py1 = _unpack_record(g, x0, x1, y0, y1)
            if px0 == px1:
                continue
            for ch in range(C):
                col[ch] = g[R_COLOR + ch]
            c0 = col[0]
            c1 = col[1]
            c2 = col[2]
            c3 = col[3]
            kk = float(k + 1)
            ws, wn = _row_window(px0, px1, x0)
            for py in range(py0, py1):
                r = py - y0
                if row_live[r] == 0:
                    continue
                dy = my - (py + PIXEL_CENTER_OFFSET)
                base = r * TILE
                if wn == QUARTER:
                    stops, kept = _fwd_row(st, base + ws, x0 + ws, QUARTER, mx, dy, a, b, c, o, lk, threshold, kk,
                                           c0, c1, c2, c3)
                elif wn == HALF:
                    stops, kept = _fwd_row(st, base + ws, x0 + ws, HALF, mx, dy, a, b, c, o, lk, threshold, kk,
                                           c0, c1, c2, c3)
                else:
                    stops, kept = _fwd_row(st, base, x0, TILE, mx, dy, a, b, c, o, lk, threshold, kk, c0, c1, c2, c3)
                row_live[r] -= stops
                live -= stops
                if kept == 0:
                    continue
                for ch in range(FUSED_CHANNELS, C):
                    cv = col[ch]
                    for i in range(ws, ws + wn):
                        p = uint64(base + i)
                        st[o_acc + uint64(ch * NPX) + p] += cv * st[o_w + p]
                if grp >= 0:
                    for px in range(px0, px1):
                        out_inst[py, px, grp] += st[F_W * NPX + base + px - x0]
        for py in range(y0, y1):
            base = (py - y0) * TILE - x0
            for px in range(x0, x1):
                p = base + px
                for ch in range(C):
                    out_color[py, px, ch] = st[(F_ACC + ch) * NPX + p]
                out_T[py, px] = st[F_T * NPX + p]
                out_last[py, px] = start + int(st[F_LAST * NPX + p])


@njit(cache=True, inline="always")
def _bwd_row(st, lanes, p0, q0, xw, width, mx, dy, a, b, c, o, lk, threshold, kf, c0, c1, c2, c3):
    """The backward's pass over ``width`` pixels of a tile row (state slots from ``p0``, lanes from
    ``q0``, image columns from ``xw``): each pixel's state update and gradient terms, then their
    per-lane sums. Branch free with unsigned indices, two fixed-width vector loops (``width`` is a
    constant at each call; two buffers, so the first loop needs no aliasing checks)."""
    o_front = uint64(B_FRONT * NPX)
    o_total = uint64(B_TOTAL * NPX)
    o_tfin = uint64(B_TFIN * NPX)
    o_ga = uint64(B_GA * NPX)
    o_end = uint64(B_END * NPX)
    o_extra = uint64(B_EXTRA * NPX)
    o_w = uint64(B_W * NPX)
    o_ds = uint64(B_DSIG * NPX)
    o_do = uint64(B_DOP * NPX)
    o_gc = uint64(B_GC * NPX)
    for i in range(width):
        p = uint64(p0 + i)
        dx = mx - (xw + i + PIXEL_CENTER_OFFSET)
        sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy
        vis = exp_neg(sigma)
        raw = o * vis
        alpha = min(ALPHA_MAX, raw)
        hit = (kf < st[o_end + p]) & (sigma >= 0.0) & (sigma <= lk) & (alpha >= threshold)
        gdot = (st[o_gc + p] * c0 + st[o_gc + uint64(NPX) + p] * c1 + st[o_gc + uint64(2 * NPX) + p] * c2
                + st[o_gc + uint64(3 * NPX) + p] * c3 + st[o_extra + p])
        Tp = st[p]  # F_T / B_T: slot 0
        wp = alpha * Tp
        fr = st[o_front + p] + gdot * wp
        one_m = 1.0 - alpha
        dl_dalpha = Tp * gdot + (st[o_ga + p] * st[o_tfin + p] - (st[o_total + p] - fr)) / one_m
        st[o_front + p] = fr if hit else st[o_front + p]
        st[p] = Tp * one_m if hit else Tp
        st[o_w + p] = wp if hit else 0.0
        grad = hit & (raw <= ALPHA_MAX)
        st[o_ds + p] = -dl_dalpha * alpha if grad else 0.0
        st[o_do + p] = dl_dalpha * vis if grad else 0.0
    for i in range(width):
        p = uint64(p0 + i)
        q = uint64(q0 + i)
        dx = mx - (xw + i + PIXEL_CENTER_OFFSET)
        ds = st[o_ds + p]
        wq = st[o_w + p]
        lanes[q] += ds * (a * dx + b * dy)
        lanes[uint64(TILE) + q] += ds * (c * dy + b * dx)
        lanes[uint64(2 * TILE) + q] += 0.5 * dx * dx * ds
        lanes[uint64(3 * TILE) + q] += dx * dy * ds
        lanes[uint64(4 * TILE) + q] += 0.5 * dy * dy * ds
        lanes[uint64(5 * TILE) + q] += st[o_do + p]
        lanes[uint64(6 * TILE) + q] += wq * st[o_gc + p]
        lanes[uint64(7 * TILE) + q] += wq * st[o_gc + uint64(NPX) + p]
        lanes[uint64(8 * TILE) + q] += wq * st[o_gc + uint64(2 * NPX) + p]
        lanes[uint64(9 * TILE) + q] += wq * st[o_gc + uint64(3 * NPX) + p]


@njit(parallel=True, cache=True)
def rasterize_bwd(means2d, conics, opac, colors, groups, n_groups, offsets, ids, width, height, tiles_x,
                  tile_size, threshold, out_color, out_T, out_inst, out_last, g_color, g_alpha, g_inst,
                  r_m2d, r_conic, r_opac, r_color, rec):
    """Gradient rows per intersection: r_* [n_isect, ...] (summed per Gaussian by ``reduce_rows``;
    views of one [n_isect, 6 + C] array keep each intersection's row in one cache line). ``rec`` is
    scratch for the packed records, as in :func:`rasterize_fwd`.

    The rows must come in zeroed: rows of Gaussians that reach no pixel are not written.
    """
    if tile_size != TILE:
        raise ValueError("the compositing kernels need tiles of TILE pixels")
    _pack_records(means2d, conics, opac, colors, groups, n_groups, threshold, rec)
    n_tiles = offsets.shape[0] - 1
    C = colors.shape[1]
    for i_tile in prange(n_tiles):
        t, tx, ty = _tile_at(i_tile, tiles_x, n_tiles // tiles_x)
        x0 = tx * TILE
        y0 = ty * TILE
        x1 = min(x0 + TILE, width)
        y1 = min(y0 + TILE, height)
        start = offsets[t]
        n = offsets[t + 1] - start
        if n == 0:
            continue
        # per-pixel state in one buffer at constant offsets from the pixel (no aliasing checks in the row
        # loop): T and front sum so far, total sum, final T, dL/dalpha_pixel, the number of Gaussians that
        # reached the pixel, the extra part of gC . c + gI (channels past the fused ones, the group), the
        # row's results (weight, dL/dsigma, dL/do), then gC per channel
        nch = max(C, FUSED_CHANNELS)
        st = np.zeros((B_GC + nch) * NPX)
        st[B_T * NPX:(B_T + 1) * NPX] = 1.0
        row_end = np.zeros(TILE, dtype=np.int64)
        n_end = 0
        for py in range(y0, y1):
            r = py - y0
            base = r * TILE - x0
            for px in range(x0, x1):
                p = base + px
                e = out_last[py, px] - start
                st[B_END * NPX + p] = e
                row_end[r] = max(row_end[r], e)
                n_end = max(n_end, e)
                st[B_TFIN * NPX + p] = out_T[py, px]
                st[B_GA * NPX + p] = g_alpha[py, px]
                tot = 0.0
                for ch in range(C):
                    gc = np.float64(g_color[py, px, ch])  # float64 products whatever the storage
                    st[(B_GC + ch) * NPX + p] = gc
                    tot += gc * out_color[py, px, ch]
                for gi in range(n_groups):
                    tot += g_inst[py, px, gi] * out_inst[py, px, gi]
                st[B_TOTAL * NPX + p] = tot
        if n_end <= 0:
            continue
        loc = np.empty((n_end, rec.shape[1]))
        _copy_records(rec, ids, start, 0, n_end, loc)
        col = np.zeros(nch)
        # per lane (tile column), summed over the rows of one Gaussian: d mean x, y, d conic a, b, c,
        # d opacity, then d colour per channel; the lanes are summed once per Gaussian
        lanes = np.zeros((6 + nch) * TILE)
        for k in range(n_end):
            g = loc[k]
            mx, my, a, b, c, o, lk, grp, px0, px1, py0, py1 = _unpack_record(g, x0, x1, y0, y1)
            if px0 == px1:
                continue
            for ch in range(C):
                col[ch] = g[R_COLOR + ch]
            c0 = col[0]
            c1 = col[1]
            c2 = col[2]
            c3 = col[3]
            kf = float(k)
            # the row window as in the forward; only its lanes are zeroed and summed
            ws, wn = _row_window(px0, px1, x0)
            for f in range(6 + nch):
                lanes[f * TILE + ws:f * TILE + ws + wn] = 0.0
            for py in range(py0, py1):
                r = py - y0
                if k >= row_end[r]:
                    continue
                dy = my - (py + PIXEL_CENTER_OFFSET)
                base = r * TILE
                extra_used = C > FUSED_CHANNELS or grp >= 0
                if extra_used:
                    for i in range(ws, ws + wn):
                        p = base + i
                        extra = 0.0
                        for ch in range(FUSED_CHANNELS, C):
                            extra += st[(B_GC + ch) * NPX + p] * col[ch]
                        st[B_EXTRA * NPX + p] = extra
                    if grp >= 0:
                        for px in range(px0, px1):
                            st[B_EXTRA * NPX + base + px - x0] += g_inst[py, px, grp]
                if wn == QUARTER:
                    _bwd_row(st, lanes, base + ws, ws, x0 + ws, QUARTER, mx, dy, a, b, c, o, lk, threshold, kf,
                             c0, c1, c2, c3)
                elif wn == HALF:
                    _bwd_row(st, lanes, base + ws, ws, x0 + ws, HALF, mx, dy, a, b, c, o, lk, threshold, kf,
                             c0, c1, c2, c3)
                else:
                    _bwd_row(st, lanes, base, 0, x0, TILE, mx, dy, a, b, c, o, lk, threshold, kf, c0, c1, c2, c3)
                if extra_used:  # the slot is zero for the next Gaussian
                    st[B_EXTRA * NPX + base + ws:B_EXTRA * NPX + base + ws + wn] = 0.0
                for ch in range(FUSED_CHANNELS, C):
                    for i in range(ws, ws + wn):
                        p = base + i
                        lanes[(6 + ch) * TILE + i] += st[B_W * NPX + p] * st[(B_GC + ch) * NPX + p]
            i0 = px0 - x0
            i1 = px1 - x0
            j = start + k
            r_m2d[j, 0] = _lane_sum(lanes, 0, i0, i1)
            r_m2d[j, 1] = _lane_sum(lanes, 1, i0, i1)
            r_conic[j, 0] = _lane_sum(lanes, 2, i0, i1)
            r_conic[j, 1] = _lane_sum(lanes, 3, i0, i1)
            r_conic[j, 2] = _lane_sum(lanes, 4, i0, i1)
            r_opac[j] = _lane_sum(lanes, 5, i0, i1)
            for ch in range(C):
                r_color[j, ch] = _lane_sum(lanes, 6 + ch, i0, i1)


@njit(cache=True, inline="always")
def _lane_sum(lanes, f, i0, i1):
    """Sum of quantity ``f``'s lanes [i0, i1) in index order (the lanes a Gaussian's box covers)."""
    s = 0.0
    for i in range(f * TILE + i0, f * TILE + i1):
        s += lanes[i]
    return s


@njit(parallel=True, cache=True)
def reduce_rows(row_start, rows, r, g_m2d, g_conic, g_opac, g_color):
    """Per Gaussian g the float64 sum of the gradient rows ``r[rows[row_start[g]:row_start[g+1]]]``
    (``r[j]`` = list position j's 2D mean, conic, opacity and colour gradients, one row per cache
    line), in list order whatever the thread count, stored in the outputs' dtype."""
    C = g_color.shape[1]
    for g in prange(row_start.shape[0] - 1):
        acc = np.zeros(6 + C)
        for p in range(row_start[g], row_start[g + 1]):
            j = rows[p]
            for f in range(6 + C):
                acc[f] += r[j, f]
        g_m2d[g, 0] = acc[0]
        g_m2d[g, 1] = acc[1]
        g_conic[g, 0] = acc[2]
        g_conic[g, 1] = acc[3]
        g_conic[g, 2] = acc[4]
        g_opac[g] = acc[5]
        for ch in range(C):
            g_color[g, ch] = acc[6 + ch]
