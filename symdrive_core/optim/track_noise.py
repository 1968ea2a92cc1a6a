"""How much a track jitters and how smoothly its vehicle moves, estimated from the track alone.

A pose refinement pulls each box towards the track at the track's error scale and smooths the
trajectory at the scale of the vehicle's real changes of motion (:mod:`.pose_refine`). Neither is
known in advance and they differ by track: a tracker's error differs by detector and distance, a
car holding its lane barely accelerates, one changing lanes does by metres per second squared.
Both come out of the track itself under the model the refinement's priors assume,

    y_f = x_f + n_f,   n_f ~ N(0, s_noise^2)        (the boxes: the path plus the track's error)
    D^k x ~ N(0, s_motion^2 I)                      (the path's k-th differences: its changes of motion)

by restricted maximum likelihood: the k-th differences of the boxes, ``z = D^k y``, do not depend
on the path's unknown start (its position, velocity), and are Gaussian with covariance
``s_motion^2 I + s_noise^2 D^k D^k^T``. Diagonalised once per piece length (``D D^T = U L U^T``),
the negative log-likelihood is ``sum_i log v_i + (U^T z)_i^2 / v_i`` with ``v_i = s_motion^2 +
s_noise^2 L_i``, minimised over a grid of both scales (log-spaced, about 6 % apart; one grid for
every floor, each scale's floor its lowest point, so a floor below an estimate never moves it).
Each axis of the track (x and y sharing scales; the yaw apart) is a column of ``y``; a track's
pieces (runs of consecutive frames) add up.

The model sees an error that changes from frame to frame, not one that changes smoothly: labels
set by hand at key frames and interpolated between have no differences between the key frames,
and a heading set once for a whole track none at all. The heading's error is therefore also
measured against the track's own path (:func:`heading_disagreement`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CEILING = 10.0  # metres (or radians) per frame^k: no real track's scale reaches it
GRID = np.geomspace(1e-4, CEILING, 200)  # each scale's candidates, about 6 % apart


def scale_grid(floor: float) -> np.ndarray:
    """The candidates of one scale: ``floor`` and every point of :data:`GRID` above it."""
    return np.concatenate([[floor], GRID[GRID > floor]])


@dataclass(frozen=True)
class TrackScales:
    """One track axis group's estimated scales (metres or radians; motion per frame^order)."""

    motion: float
    noise: float


def estimate_scales(pieces: list[np.ndarray], order: int, motion_floor: float,
                    noise_floor: float) -> TrackScales | None:
    """The restricted maximum-likelihood scales of ``pieces`` (each ``[n, k]``: ``n`` consecutive
    frames of ``k`` axes that share the scales), each at least its floor; None where no piece is
    longer than ``order + 1`` frames (too short to tell motion from noise)."""
    spectra = []
    for y in pieces:
        y = np.asarray(y, dtype=np.float64).reshape(len(y), -1)
        n = len(y)
        if n <= order + 1:
            continue
        D = np.diff(np.eye(n), order, axis=0)
        lam, U = np.linalg.eigh(D @ D.T)
        z2 = ((U.T @ (D @ y)) ** 2).sum(axis=1)  # summed over the axes sharing the scales
        spectra.append((lam, z2, y.shape[1]))
    if not spectra:
        return None
    motion, noise = scale_grid(motion_floor), scale_grid(noise_floor)
    nll = np.zeros((len(motion), len(noise)))
    for lam, z2, axes in spectra:
        for i, m in enumerate(motion):  # a row at a time: a long track's spectrum stays small
            v = m * m + noise[:, None] ** 2 * lam[None, :]
            nll[i] += (axes * np.log(v) + z2 / v).sum(axis=1)
    i, j = np.unravel_index(np.argmin(nll), nll.shape)
    return TrackScales(float(motion[i]), float(noise[j]))


def heading_disagreement(centres: list[np.ndarray], headings: list[np.ndarray], chord_m: float) -> float | None:
    """The RMS angle (modulo pi: the slip cannot tell forwards from backwards) between each box's
    heading and its path: the chord of the shortest span of at least ``chord_m`` metres centred on
    it (clipped at the piece's ends), over the pieces' ``[n, 2]`` centres and ``[n]`` headings;
    None where fewer than three boxes have such a chord (a parked or crawling vehicle)."""
    angles = []
    for xy, yaw in zip(centres, headings):
        xy, n = np.asarray(xy, dtype=np.float64), len(xy)
        frame = np.arange(n)
        chord = np.full((n, 2), np.nan)
        for k in range(1, n):  # spans widened for every box at once: a long parked track stays fast
            d = xy[np.minimum(frame + k, n - 1)] - xy[np.maximum(frame - k, 0)]
            reached = np.isnan(chord[:, 0]) & (np.hypot(d[:, 0], d[:, 1]) >= chord_m)
            chord[reached] = d[reached]
            if not np.isnan(chord[:, 0]).any():
                break
        found = ~np.isnan(chord[:, 0])
        angle = np.arctan2(chord[found, 1], chord[found, 0]) - np.asarray(yaw)[found]
        angles.extend((angle + np.pi / 2) % np.pi - np.pi / 2)
    return float(np.sqrt(np.mean(np.square(angles)))) if len(angles) >= 3 else None
