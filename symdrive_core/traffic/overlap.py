"""Per-frame check that no two vehicles' bounding boxes overlap, and the smallest gap between any two.

All vehicles stand on the road with yaw-only rotations, so their boxes overlap in 3D exactly
when their ground footprints (oriented rectangles) overlap: a separating-axis test in 2D. The
gap between two disjoint rectangles is the smallest corner-to-edge distance either way.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import SymDriveError
from ..scene import Actor
from ..scene.poses import yaw_of

PENETRATION_TOL_M = 1e-6


class OverlapError(SymDriveError):
    """Two vehicles' boxes overlap in some frame."""


@dataclass
class GapReport:
    min_gap: float | None = None  # metres; None with fewer than two vehicles in every frame
    frame: int | None = None
    pair: tuple[str, str] | None = None
    overlaps: list[tuple[int, str, str]] = field(default_factory=list)  # (frame, actor, actor)

    def to_json(self) -> dict:
        return {"min_gap_m": self.min_gap, "frame": self.frame, "pair": list(self.pair) if self.pair else None,
                "overlaps": [list(o) for o in self.overlaps]}


def footprints(centre: np.ndarray, yaw: np.ndarray, wlh: np.ndarray) -> np.ndarray:
    """Ground rectangles [N, 4, 2], corners counter-clockwise."""
    fwd = np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
    left = np.stack([-fwd[:, 1], fwd[:, 0]], axis=1)
    hl, hw = 0.5 * wlh[:, 1:2], 0.5 * wlh[:, 0:1]
    signs = np.array([[1, -1], [1, 1], [-1, 1], [-1, -1]], dtype=np.float64)
    return (centre[:, None] + signs[None, :, 0:1] * (hl * fwd)[:, None]
            + signs[None, :, 1:2] * (hw * left)[:, None])


def _separated(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[P] True where rectangles a[P,4,2], b[P,4,2] have a separating axis (touching counts)."""
    sep = np.zeros(len(a), dtype=bool)
    for rect in (a, b):
        for e in (0, 1):
            axis = rect[:, e + 1] - rect[:, e]
            pa = np.einsum("pkd,pd->pk", a, axis)
            pb = np.einsum("pkd,pd->pk", b, axis)
            scale = np.linalg.norm(axis, axis=1)
            gap = np.maximum(pb.min(1) - pa.max(1), pa.min(1) - pb.max(1)) / scale
            sep |= gap > -PENETRATION_TOL_M
    return sep


def _corner_edge_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[P] smallest distance from a corner of ``a`` to an edge of ``b``."""
    p = a[:, :, None, :]  # [P, 4, 1, 2]
    s0, s1 = b[:, None, :, :], np.roll(b, -1, axis=1)[:, None, :, :]
    d = s1 - s0
    u = np.clip(np.sum((p - s0) * d, -1) / np.sum(d * d, -1), 0.0, 1.0)
    return np.linalg.norm(p - (s0 + u[..., None] * d), axis=-1).min(axis=(1, 2))


def frame_gaps(rects: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For rectangles [N, 4, 2]: pair indices i, j and each pair's gap (negative = overlap)."""
    i, j = np.triu_indices(len(rects), k=1)
    a, b = rects[i], rects[j]
    gap = np.minimum(_corner_edge_distance(a, b), _corner_edge_distance(b, a))
    return i, j, np.where(_separated(a, b), gap, -1.0)


def check_actors(actors: list[Actor], n_frames: int) -> GapReport:
    """Gap report over every frame; overlaps are listed, not raised (see :func:`require_no_overlap`)."""
    report = GapReport()
    wlh = np.array([a.wlh for a in actors]) if actors else np.zeros((0, 3))
    for f in range(n_frames):
        idx = [k for k, a in enumerate(actors) if a.poses[f] is not None]
        if len(idx) < 2:
            continue
        centre = np.array([actors[k].poses[f].translation[:2] for k in idx])
        yaw = np.array([yaw_of(actors[k].poses[f].rotation) for k in idx])
        i, j, gap = frame_gaps(footprints(centre, yaw, wlh[idx]))
        for k in np.flatnonzero(gap < 0):
            report.overlaps.append((f, actors[idx[i[k]]].id, actors[idx[j[k]]].id))
        k = int(np.argmin(np.where(gap >= 0, gap, np.inf)))
        if gap[k] >= 0 and (report.min_gap is None or gap[k] < report.min_gap):
            report.min_gap, report.frame = float(gap[k]), f
            report.pair = (actors[idx[i[k]]].id, actors[idx[j[k]]].id)
    return report


def require_no_overlap(report: GapReport) -> None:
    if report.overlaps:
        shown = ", ".join(f"frame {f}: {a} and {b}" for f, a, b in report.overlaps[:5])
        more = f" (and {len(report.overlaps) - 5} more)" if len(report.overlaps) > 5 else ""
        raise OverlapError(f"vehicle boxes overlap in {len(report.overlaps)} case(s): {shown}{more}")
