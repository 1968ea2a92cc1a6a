"""Tile lists cut to the tiles a Gaussian's ellipse reaches (``bin_gaussians`` given conics and
opacities) against lists of every tile of its rectangle: fewer tile-Gaussian pairs, the same image
and the same gradients, since a Gaussian is skipped at every pixel of a tile its ellipse misses."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from symdrive_core.splat import kernels
from symdrive_core.splat.rasterizer import bin_gaussians

from .test_kernels_baseline import N_GROUPS, THRESHOLD, backward, forward, scene_2d


def tilted_scene(n, width, height, seed):
    """Elongated Gaussians at random angles (most boxes cover tiles their ellipse misses)."""
    rng = np.random.default_rng(seed)
    means = rng.uniform([-10.0, -10.0], [width + 10.0, height + 10.0], size=(n, 2))
    major = np.exp(rng.uniform(math.log(3.0), math.log(25.0), n))
    minor = np.exp(rng.uniform(math.log(0.3), math.log(2.0), n))
    angle = rng.uniform(0.0, math.pi, n)
    cs, sn = np.cos(angle), np.sin(angle)
    cov = np.stack([major ** 2 * cs ** 2 + minor ** 2 * sn ** 2, (major ** 2 - minor ** 2) * cs * sn,
                    major ** 2 * sn ** 2 + minor ** 2 * cs ** 2], 1)
    det = cov[:, 0] * cov[:, 2] - cov[:, 1] ** 2
    conics = np.stack([cov[:, 2] / det, -cov[:, 1] / det, cov[:, 0] / det], 1)
    opac = rng.uniform(0.05, 1.0, n)
    opac[:n // 10] = 0.99
    k = np.minimum(np.sqrt(2.0 * np.log(np.maximum(opac / THRESHOLD, 1.0))), 3.33)
    radii = np.ceil(k[:, None] * np.sqrt(cov[:, [0, 2]])).astype(np.int64)
    colors = rng.uniform(0.0, 1.0, (n, 4))
    groups = rng.integers(-1, N_GROUPS, n)
    return means, conics, opac, colors, groups, radii, rng.uniform(1.0, 50.0, n)


def both_bins(means, conics, opac, radii, depths, width, height, dtype):
    t = [torch.from_numpy(np.ascontiguousarray(a)) for a in (means.astype(dtype), radii, depths.astype(dtype),
                                                             conics.astype(dtype), opac.astype(dtype))]
    box = bin_gaussians(t[0], t[1], t[2], width, height)
    cut = bin_gaussians(t[0], t[1], t[2], width, height, conics=t[3], opacities=t[4], threshold=THRESHOLD)
    return box, cut


def per_gaussian(bins, rows):
    """Gradient rows summed per Gaussian (the reduction the frame path runs)."""
    m = bins.row_start.shape[0] - 1
    r = np.concatenate([rows[0], rows[1], rows[2][:, None], rows[3]], 1)
    out = [np.empty((m, 2)), np.empty((m, 3)), np.empty(m), np.empty((m, rows[3].shape[1]))]
    kernels.reduce_rows(bins.row_start, bins.rows, r, *out)
    return out


CASES = [("tilted", 300, 70, 50), ("tiny", 400, 61, 45), ("huge", 60, 64, 48), ("mixed", 300, 70, 50),
         ("dense", 400, 33, 47)]


@pytest.mark.parametrize("kind,n,width,height", CASES)
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_cut_lists_give_the_box_lists_image_and_gradients(kind, n, width, height, dtype):
    scene = tilted_scene(n, width, height, 0) if kind == "tilted" else scene_2d(n, width, height, 0, kind)
    means, conics, opac, colors, groups, radii, depths = scene
    box, cut = both_bins(means, conics, opac, radii, depths, width, height, dtype)
    outs, grads = [], []
    for bins in (box, cut):
        args = (means.astype(dtype), conics.astype(dtype), opac.astype(dtype), colors.astype(dtype), groups,
                N_GROUPS, bins.offsets, bins.ids, width, height, bins.tiles_x, kernels.TILE, THRESHOLD)
        out = forward(kernels, args)
        outs.append(out)
        grads.append(per_gaussian(bins, backward(kernels, args, out, 0)))
    for got, want in zip(outs[1][:3], outs[0][:3]):
        np.testing.assert_allclose(got, want, atol=1e-12, rtol=0)
    for got, want in zip(grads[1], grads[0]):
        np.testing.assert_allclose(got, want, atol=1e-12 * max(1.0, float(np.abs(want).max())), rtol=0)
    assert cut.n_isect <= box.n_isect
    if kind == "tilted":
        assert cut.n_isect < 0.9 * box.n_isect


def test_tile_the_ellipse_misses_gets_no_entry():
    """A thin Gaussian along the image diagonal: its rectangle is 4 x 4 tiles, its ellipse misses the
    far corners (and every tile away from the diagonal), which get no entry; the tiles it crosses
    keep theirs."""
    major, minor = 12.0, 0.8
    cs = sn = math.sqrt(0.5)
    cov = np.array([major ** 2 * cs ** 2 + minor ** 2 * sn ** 2, (major ** 2 - minor ** 2) * cs * sn,
                    major ** 2 * sn ** 2 + minor ** 2 * cs ** 2])
    det = cov[0] * cov[2] - cov[1] ** 2
    conics = np.array([[cov[2] / det, -cov[1] / det, cov[0] / det]])
    opac = np.array([0.9])
    k = min(math.sqrt(2.0 * math.log(0.9 / THRESHOLD)), 3.33)
    radii = np.ceil(k * np.sqrt(cov[[0, 2]]))[None].astype(np.int64)
    means = np.array([[32.0, 32.0]])
    box, cut = both_bins(means, conics, opac, radii, np.array([5.0]), 64, 64, np.float64)

    def tiles(bins):
        return {t for t in range(16) if bins.offsets[t + 1] > bins.offsets[t]}

    assert tiles(box) == set(range(16))
    assert {0, 5, 10, 15} <= tiles(cut)  # the diagonal tiles (tile t = 4 ty + tx)
    assert not {3, 12, 2, 8, 7, 13} & tiles(cut)  # far from the diagonal
    np.testing.assert_array_equal(cut.rows, np.arange(cut.n_isect))  # one Gaussian: its positions in order
    assert cut.row_start.tolist() == [0, cut.n_isect]
