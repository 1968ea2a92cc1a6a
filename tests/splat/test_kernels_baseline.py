"""The box-clipped, Gaussian-outer tile kernels against the pixel-outer baseline they replace.

Both get the same tile lists and inputs; the forward must give the same colours, transmittance,
instance weights and last indices, and the backward the same gradient rows, on scenes built to hit
the edges of the box rule: tiny and huge Gaussians, opacity at 0.99 and at the threshold, early
termination, Gaussians across tile borders, non-positive-definite conics and image sizes that are
not multiples of 16.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from symdrive_core.bench import kernels_baseline, rasterize_baseline
from symdrive_core.splat import kernels

THRESHOLD = 1.0 / 255.0
N_GROUPS = 3


def scene_2d(n, width, height, seed, kind):
    """2D Gaussians (means, conics, opacities, colours, groups, radii, depths) of one hard case."""
    rng = np.random.default_rng(seed)
    means = rng.uniform([-8.0, -8.0], [width + 8.0, height + 8.0], size=(n, 2))
    log_sd = {"tiny": (-2.5, -0.5), "huge": (2.0, 4.0), "mixed": (-2.5, 3.5), "dense": (0.5, 2.0)}[kind]
    sd = np.exp(rng.uniform(*log_sd, size=(n, 2)))
    rho = rng.uniform(-0.95, 0.95, n)
    cov = np.stack([sd[:, 0] ** 2, rho * sd[:, 0] * sd[:, 1], sd[:, 1] ** 2], 1)
    det = cov[:, 0] * cov[:, 2] - cov[:, 1] ** 2
    conics = np.stack([cov[:, 2] / det, -cov[:, 1] / det, cov[:, 0] / det], 1)
    opac = rng.uniform(0.05, 1.0, n)
    if kind == "dense":
        opac = rng.uniform(0.9, 1.0, n)
    # opacities on the rule's edges: at the alpha cap, just around the threshold, zero
    edge = rng.random(n)
    opac[edge < 0.08] = 0.99
    opac[(edge >= 0.08) & (edge < 0.16)] = THRESHOLD * rng.uniform(0.999, 1.001, int(((edge >= 0.08) & (edge < 0.16)).sum()))
    opac[(edge >= 0.16) & (edge < 0.18)] = 0.0
    if kind == "mixed":  # some Gaussians whose conic the box rule cannot bound (full-tile fallback)
        bad = rng.random(n) < 0.05
        conics[bad, 1] = np.sqrt(conics[bad, 0] * conics[bad, 2]) * rng.uniform(1.0, 1.5, int(bad.sum()))
    colors = rng.uniform(0.0, 1.0, (n, 4))
    groups = rng.integers(-1, 3, n)
    radii = np.ceil(3.33 * sd).astype(np.int64)
    depths = rng.uniform(1.0, 50.0, n)
    return means, conics, opac, colors, groups, radii, depths


def bins_of(means, radii, depths, width, height):
    tiles_x = (width + kernels.TILE - 1) // kernels.TILE
    tiles_y = (height + kernels.TILE - 1) // kernels.TILE
    rects = rasterize_baseline.tile_rects(means, radii, kernels.TILE, tiles_x, tiles_y)
    offsets, ids = rasterize_baseline.bin_tiles(np.argsort(depths, kind="stable"), rects, tiles_x, tiles_y)
    return offsets, ids, tiles_x


def kernel_args(means, conics, opac, colors, groups, offsets, ids, tiles_x, width, height, dtype):
    return (means.astype(dtype), conics.astype(dtype), opac.astype(dtype), colors.astype(dtype), groups, N_GROUPS,
            offsets, ids, width, height, tiles_x, kernels.TILE, THRESHOLD)


def records(module, args):
    """The current kernels' scratch for packed records (filled with garbage: it is only scratch)."""
    if module is not kernels:
        return ()
    return (np.full((args[0].shape[0], kernels.R_COLOR + args[3].shape[1]), np.nan),)


def forward(module, args):
    """Colour, T, instance weights and last index of one kernel module's forward."""
    width, height, colors = args[8], args[9], args[3]
    out = (np.zeros((height, width, colors.shape[1]), colors.dtype), np.ones((height, width)),
           np.zeros((height, width, N_GROUPS), colors.dtype), np.zeros((height, width), np.int64))
    module.rasterize_fwd(*args, *out, *records(module, args))
    return out


def backward(module, args, fwd_out, seed):
    """Gradient rows of one kernel module's backward for random output gradients."""
    width, height, colors = args[8], args[9], args[3]
    C, dtype, m = colors.shape[1], colors.dtype, args[7].shape[0]
    rng = np.random.default_rng(seed + 100)
    grads = (rng.normal(size=(height, width, C)).astype(dtype), rng.normal(size=(height, width)).astype(dtype),
             rng.normal(size=(height, width, N_GROUPS)).astype(dtype))
    rows = (np.zeros((m, 2), dtype), np.zeros((m, 3), dtype), np.zeros(m, dtype), np.zeros((m, C), dtype))
    module.rasterize_bwd(*args, *fwd_out, *grads, *rows, *records(module, args))
    return rows


CASES = [("tiny", 400, 61, 45), ("huge", 60, 64, 48), ("mixed", 300, 70, 50), ("dense", 400, 33, 47)]


@pytest.mark.parametrize("kind,n,width,height", CASES)
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("seed", [0, 1])
def test_kernels_match_baseline(kind, n, width, height, dtype, seed):
    means, conics, opac, colors, groups, radii, depths = scene_2d(n, width, height, seed, kind)
    offsets, ids, tiles_x = bins_of(means, radii, depths, width, height)
    args = kernel_args(means, conics, opac, colors, groups, offsets, ids, tiles_x, width, height, dtype)
    color, T, inst, last = forward(kernels, args)
    base_out = forward(kernels_baseline, args)
    color_b, T_b, inst_b, last_b = base_out
    np.testing.assert_array_equal(last, last_b)  # the same Gaussians reached every pixel
    tol = 1e-12 if dtype == np.float64 else 1e-6
    np.testing.assert_allclose(T, T_b, atol=1e-12, rtol=0)
    np.testing.assert_allclose(color, color_b, atol=tol, rtol=0)
    np.testing.assert_allclose(inst, inst_b, atol=tol, rtol=0)
    # both backward passes from the same forward outputs (float32 storage rounds each forward's own)
    rows = backward(kernels, args, base_out, seed)
    rows_b = backward(kernels_baseline, args, base_out, seed)
    for got, want in zip(rows, rows_b):
        scale = max(1.0, float(np.abs(want).max()))
        np.testing.assert_allclose(got, want, atol=tol * scale, rtol=0)
    # the scene exercises what it is meant to
    assert ids.shape[0] > 0 and float(T.max()) > float(T.min())
    if kind == "dense":
        assert float((T <= 1e-2).mean()) > 0.5  # most pixels terminate early


def test_every_row_window_matches_the_baseline():
    """Boxes one to sixteen pixels wide at every column of their tile, so each of the row windows
    (a quarter, half or whole tile row, its start clamped at the tile's right edge) runs, in float64:
    the same images and gradient rows as the pixel-outer baseline, which evaluates every pixel."""
    width, height = 48, 40
    rng = np.random.default_rng(11)
    n = 600
    means = np.stack([rng.uniform(0.0, width, n), rng.uniform(0.0, height, n)], 1)
    sd = np.exp(rng.uniform(-1.5, 1.2, (n, 2)))  # boxes of 1 to about 16 pixels
    conics = np.stack([1.0 / sd[:, 0] ** 2, np.zeros(n), 1.0 / sd[:, 1] ** 2], 1)
    opac = rng.uniform(0.05, 0.99, n)
    colors = rng.uniform(0.0, 1.0, (n, 4))
    groups = rng.integers(-1, N_GROUPS, n)
    radii = np.ceil(3.33 * sd).astype(np.int64)
    depths = rng.uniform(1.0, 50.0, n)
    windows = set()
    for i in range(n):
        lim = kernels.sigma_limit(opac[i], THRESHOLD)
        hx, _ = kernels.ellipse_half_extent(conics[i, 0], conics[i, 1], conics[i, 2], lim)
        x0 = int(means[i, 0] // kernels.TILE) * kernels.TILE
        px0, px1 = kernels.pixel_span(means[i, 0], hx, x0, min(x0 + kernels.TILE, width))
        if px1 > px0:
            ws, wn = kernels._row_window(px0, px1, x0)
            assert ws <= px0 - x0 and px1 - x0 <= ws + wn <= kernels.TILE  # the window holds the box
            windows.add((wn, ws == kernels.TILE - wn and px0 - x0 > ws))
    assert {(kernels.QUARTER, True), (kernels.HALF, True), (kernels.QUARTER, False), (kernels.HALF, False),
            (kernels.TILE, False)} <= windows
    offsets, ids, tiles_x = bins_of(means, radii, depths, width, height)
    args = kernel_args(means, conics, opac, colors, groups, offsets, ids, tiles_x, width, height, np.float64)
    out = forward(kernels, args)
    out_b = forward(kernels_baseline, args)
    np.testing.assert_array_equal(out[3], out_b[3])
    for got, want in zip(out[:3], out_b[:3]):
        np.testing.assert_allclose(got, want, atol=1e-12, rtol=0)
    for got, want in zip(backward(kernels, args, out_b, 0), backward(kernels_baseline, args, out_b, 0)):
        np.testing.assert_allclose(got, want, atol=1e-12 * max(1.0, float(np.abs(want).max())), rtol=0)


def test_box_holds_every_pixel_the_rule_keeps():
    """Pixels outside a Gaussian's box have sigma above its limit (the rule skips them)."""
    rng = np.random.default_rng(3)
    for _ in range(2000):
        sd = np.exp(rng.uniform(-2.0, 3.0, 2))
        rho = rng.uniform(-0.999, 0.999)
        cov = np.array([[sd[0] ** 2, rho * sd[0] * sd[1]], [rho * sd[0] * sd[1], sd[1] ** 2]])
        a, b, c = np.linalg.inv(cov)[[0, 0, 1], [0, 1, 1]]
        o = rng.choice([THRESHOLD * 1.0001, 0.5, 0.99])
        lim = kernels.sigma_limit(o, THRESHOLD)
        hx, hy = kernels.ellipse_half_extent(a, b, c, lim)
        m = rng.uniform(-20.0, 20.0, 2)
        px0, px1 = kernels.pixel_span(m[0], hx, -64, 64)
        py0, py1 = kernels.pixel_span(m[1], hy, -64, 64)
        py, px = np.mgrid[-64:64, -64:64]
        dx = m[0] - (px + 0.5)
        dy = m[1] - (py + 0.5)
        sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy
        inside = (px >= px0) & (px < px1) & (py >= py0) & (py < py1)
        assert not np.any((sigma <= lim) & ~inside)
        # and the box is tight: it is at most one pixel wider than the ellipse on each side
        assert px1 - px0 <= 2 * hx + 2 and py1 - py0 <= 2 * hy + 2
        assert math.isfinite(hx) and math.isfinite(hy)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_depth_order_is_a_stable_argsort(dtype):
    rng = np.random.default_rng(5)
    depths = np.concatenate([rng.uniform(0.01, 1e4, 5000), rng.integers(0, 20, 3000) * 0.5,  # many ties
                             [0.0, -0.0, -3.0, np.inf, 1e-30, 5e30]]).astype(dtype)
    rng.shuffle(depths)
    np.testing.assert_array_equal(kernels.depth_order(depths), np.argsort(depths, kind="stable"))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_binning_and_reduction_match_the_baseline(dtype):
    """Depth-ordered rectangles and Gaussian-ordered gradient rows give the baseline's tile lists and,
    bit for bit, its serial per-Gaussian sums."""
    width, height = 200, 120
    means, conics, opac, colors, groups, radii, depths = scene_2d(3000, width, height, 4, "mixed")
    radii[::7] = 0  # culled Gaussians: no tiles, zero gradient
    offsets_b, ids_b, tiles_x = bins_of(means, radii, depths, width, height)
    tiles_y = (height + 15) // 16
    order = kernels.depth_order(depths.astype(dtype))
    rects = kernels.tile_rects(means.astype(dtype), radii.astype(np.int32), order, kernels.TILE, tiles_x, tiles_y)
    offsets, ids, row_start, rows = kernels.bin_tiles(order, rects, tiles_x, tiles_y, np.zeros(0, np.uint64))
    np.testing.assert_array_equal(offsets, offsets_b)
    np.testing.assert_array_equal(ids, ids_b)
    m, n_isect = means.shape[0], ids.shape[0]
    for g in range(m):  # Gaussian g's list positions, increasing
        np.testing.assert_array_equal(rows[row_start[g]:row_start[g + 1]], np.flatnonzero(ids == g))
    packed = np.random.default_rng(9).normal(size=(n_isect, 10)).astype(dtype)
    r = [packed[:, 0:2], packed[:, 2:5], packed[:, 5], packed[:, 6:]]
    want = [np.zeros((m,) + a.shape[1:]) for a in r]
    rasterize_baseline.reduce_rows(ids, *r, *want)
    got = [np.empty((m,) + a.shape[1:], dtype) for a in r]
    kernels.reduce_rows(row_start, rows, packed, *got)
    for a, b in zip(got, want):
        np.testing.assert_array_equal(a, b.astype(dtype))


def test_vector_exp_is_within_two_ulp_of_libm():
    s = np.concatenate([np.random.default_rng(6).uniform(0.0, 8.0, 20000), np.linspace(0.0, 744.0, 5000),
                        [0.0, 1e-300, 5e-324, 744.0]])
    got = np.array([kernels.exp_neg(v) for v in s])
    want = np.exp(-s)
    assert np.all(np.abs(got - want) <= 2 * np.spacing(want))


def test_power_of_two_scale_is_exact():
    """exp_neg's 2^-k from bits equals 2.0 ** -k for every k it can take, subnormals included."""
    got = np.array([kernels.pow2_neg(k) for k in range(1075)])
    np.testing.assert_array_equal(got, 2.0 ** -np.arange(1075.0))


@pytest.mark.parametrize("tiles_x,tiles_y", [(80, 45), (5, 3), (1, 1), (7, 9), (3, 4), (1, 6)])
def test_tile_order_visits_every_tile_once(tiles_x, tiles_y):
    got = [kernels._tile_at(i, tiles_x, tiles_y) for i in range(tiles_x * tiles_y)]
    assert sorted(t for t, _, _ in got) == list(range(tiles_x * tiles_y))
    assert all(t == ty * tiles_x + tx and 0 <= tx < tiles_x and 0 <= ty < tiles_y for t, tx, ty in got)
