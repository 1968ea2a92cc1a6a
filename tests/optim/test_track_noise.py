"""A track's jitter and its vehicle's changes of motion, estimated from the track alone: the
spectral shortcut picks the grid point a float64 dense-covariance likelihood picks, known scales
come back from long simulated tracks, and the hard cases (no noise, no motion, too short) land
where they must."""

from __future__ import annotations

import numpy as np
import pytest

from symdrive_core.optim import track_noise
from symdrive_core.optim.track_noise import estimate_scales, heading_disagreement


def _simulated(rng, n_frames: int, motion: float, noise: float, order: int, axes: int) -> np.ndarray:
    """A path whose ``order``-th differences are N(0, motion^2), seen with N(0, noise^2) error."""
    path = rng.normal(0.0, motion, size=(n_frames, axes))
    for _ in range(order):
        path = np.cumsum(path, axis=0)
    return path + rng.normal(0.0, noise, size=path.shape)


def test_the_estimate_is_the_dense_likelihoods_grid_minimum():
    """The same grid, the negative log-likelihood of the differenced track written out with its
    dense covariance, through its batched eigendecomposition in float64 (log-determinant and
    quadratic form; a batched ``solve`` of these small systems costs seconds on a loaded BLAS):
    the same grid point."""
    rng = np.random.default_rng(4)
    pieces = [_simulated(rng, 9, 0.05, 0.1, 2, 2), _simulated(rng, 6, 0.05, 0.1, 2, 2)]
    floors = (0.005, 0.01)
    motion, noise = track_noise.scale_grid(floors[0]), track_noise.scale_grid(floors[1])
    a2, s2 = (motion ** 2)[:, None, None, None], (noise ** 2)[None, :, None, None]
    nll = np.zeros((len(motion), len(noise)))
    for y in pieces:
        D = np.diff(np.eye(len(y)), 2, axis=0)
        cov = a2 * np.eye(len(D)) + s2 * (D @ D.T)
        w, V = np.linalg.eigh(cov)
        proj = np.swapaxes(V, -1, -2) @ (D @ y)  # the differences in the covariance's eigenbasis
        nll += y.shape[1] * np.log(w).sum(axis=-1) + np.sum(proj ** 2 / w[..., None], axis=(2, 3))
    i, j = np.unravel_index(np.argmin(nll), nll.shape)
    got = estimate_scales(pieces, 2, *floors)
    assert (got.motion, got.noise) == (motion[i], noise[j])


def test_known_scales_come_back_from_long_tracks():
    """Forty pieces of 30 frames drawn from the model (acceleration 5 cm per frame squared,
    error 20 cm; and a jerk model): both scales within 15 %."""
    rng = np.random.default_rng(0)
    for order, motion, noise in ((2, 0.05, 0.2), (3, 0.02, 0.1)):
        pieces = [_simulated(rng, 30, motion, noise, order, 2) for _ in range(40)]
        got = estimate_scales(pieces, order, 1e-3, 1e-3)
        assert abs(got.motion / motion - 1) < 0.15 and abs(got.noise / noise - 1) < 0.15, (order, got)


def test_the_hard_cases():
    """A constant-velocity track without error: both scales at their floors (its differences are
    zero to round-off); error without motion: the motion at its floor and the error found; one
    piece too short to tell the two apart: no estimate."""
    f = np.arange(20.0)[:, None]
    line = np.hstack([3.0 + 1.4 * f, -2.0 + 0.1 * f])
    got = estimate_scales([line], 2, 0.005, 0.01)
    assert (got.motion, got.noise) == (0.005, 0.01)
    rng = np.random.default_rng(1)
    jitter = [line + rng.normal(0.0, 0.1, size=line.shape) for _ in range(10)]
    got = estimate_scales(jitter, 2, 0.005, 0.01)
    assert got.motion < 0.01 and abs(got.noise / 0.1 - 1) < 0.15, got
    assert estimate_scales([line[:3]], 2, 0.005, 0.01) is None
    assert estimate_scales([line[:4]], 2, 0.005, 0.01) is not None


def test_a_floor_below_the_estimate_leaves_it_where_it_is():
    """The grid is one for every floor: raising the error's floor from 1 to 10 cm under a track
    jittering by 20 cm changes nothing; raised above the jitter, the estimate sits on the floor."""
    rng = np.random.default_rng(2)
    pieces = [_simulated(rng, 25, 0.02, 0.2, 2, 2) for _ in range(6)]
    low, high = estimate_scales(pieces, 2, 0.005, 0.01), estimate_scales(pieces, 2, 0.005, 0.1)
    assert low == high and low.noise > 0.1
    assert estimate_scales(pieces, 2, 0.005, 0.5).noise == 0.5


def test_a_heading_off_its_path_is_measured_against_the_chord():
    """Boxes driving along x with every heading 5 degrees off (a hand-set heading, smooth, whose
    differences see nothing): 5 degrees; turned by pi (a label pointing backwards, which the slip
    cannot tell): the same; on its path: zero; a parked car's boxes never span the chord: no
    estimate."""
    x = np.arange(30.0) * 0.6
    xy = np.stack([x, 0.01 * np.sin(x)], axis=1)
    off = np.full(30, np.radians(5.0))
    assert abs(heading_disagreement([xy], [off], 4.0) - np.radians(5.0)) < 1e-3
    assert heading_disagreement([xy], [off + np.pi], 4.0) == pytest.approx(np.radians(5.0), abs=1e-3)
    assert heading_disagreement([xy], [np.zeros(30)], 4.0) < 0.005  # the path wiggles by a centimetre
    parked = np.random.default_rng(0).normal(0.0, 0.03, size=(30, 2))
    assert heading_disagreement([parked], [np.zeros(30)], 4.0) is None
