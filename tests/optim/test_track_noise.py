"""A track's jitter and its vehicle's changes of motion, estimated from the track alone: the
spectral shortcut picks the grid point a float64 dense-covariance likelihood picks, known scales
come back from long simulated tracks, and the hard cases (no noise, no motion, too short) land
where they must."""

from __future__ import annotations

import numpy as np

from symdrive_core.optim import track_noise
from symdrive_core.optim.track_noise import estimate_scales


def _simulated(rng, n_frames: int, motion: float, noise: float, order: int, axes: int) -> np.ndarray:
    """A path whose ``order``-th differences are N(0, motion^2), seen with N(0, noise^2) error."""
    path = rng.normal(0.0, motion, size=(n_frames, axes))
    for _ in range(order):
        path = np.cumsum(path, axis=0)
    return path + rng.normal(0.0, noise, size=path.shape)


def test_the_estimate_is_the_dense_likelihoods_grid_minimum():
    """The same grid, the negative log-likelihood of the differenced track written out with its
    dense covariance (batched ``slogdet`` and ``solve`` in float64): the same grid point."""
    rng = np.random.default_rng(4)
    pieces = [_simulated(rng, 9, 0.05, 0.1, 2, 2), _simulated(rng, 6, 0.05, 0.1, 2, 2)]
    floors = (0.005, 0.01)
    steps = track_noise.GRID_STEPS
    motion = np.geomspace(floors[0], track_noise.CEILING, steps)
    noise = np.geomspace(floors[1], track_noise.CEILING, steps)
    a2, s2 = (motion ** 2)[:, None, None, None], (noise ** 2)[None, :, None, None]
    nll = np.zeros((steps, steps))
    for y in pieces:
        D = np.diff(np.eye(len(y)), 2, axis=0)
        cov = a2 * np.eye(len(D)) + s2 * (D @ D.T)
        z = np.broadcast_to(D @ y, (steps, steps, len(D), y.shape[1]))
        nll += y.shape[1] * np.linalg.slogdet(cov)[1] + np.sum(z * np.linalg.solve(cov, z), axis=(2, 3))
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
