"""Arc-length sampling of a polyline (a Blender curve's evaluated geometry), numpy only."""

from __future__ import annotations

import numpy as np


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


class Polyline:
    """Points in order along a path; positions and tangents at given distances from the start.

    Tangents are blended linearly between vertex tangents (the mean of the two adjacent
    segment directions; extrapolated at open ends), so headings turn smoothly instead of
    jumping at every vertex.
    """

    def __init__(self, points, cyclic: bool = False):
        pts = np.asarray(points, dtype=np.float64)
        keep = np.ones(len(pts), dtype=bool)  # drop repeated points (zero-length segments)
        keep[1:] = np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-9
        pts = pts[keep]
        if cyclic and len(pts) > 1 and np.linalg.norm(pts[0] - pts[-1]) > 1e-9:
            pts = np.vstack([pts, pts[:1]])
        if len(pts) < 2:
            raise ValueError("a path needs at least two distinct points")
        self.points, self.cyclic = pts, cyclic
        seg = np.diff(pts, axis=0)
        self.cumulative = np.concatenate([[0.0], np.cumsum(np.linalg.norm(seg, axis=1))])
        d = _unit(seg)
        tangents = np.empty_like(pts)
        tangents[1:-1] = d[:-1] + d[1:]
        if cyclic:
            tangents[0] = tangents[-1] = d[-1] + d[0]
        elif len(d) > 1:  # open ends: extrapolate from the chord and the next vertex tangent
            tangents[0] = 2 * d[0] - _unit(tangents[1])
            tangents[-1] = 2 * d[-1] - _unit(tangents[-2])
        else:
            tangents[0] = tangents[-1] = d[0]
        self.tangents = _unit(tangents)

    @property
    def length(self) -> float:
        return float(self.cumulative[-1])

    def sample(self, distances) -> tuple[np.ndarray, np.ndarray]:
        """Positions [N, 3] and unit tangents [N, 3]; distances wrap on cyclic paths, clamp otherwise."""
        s = np.asarray(distances, dtype=np.float64)
        s = np.mod(s, self.length) if self.cyclic else np.clip(s, 0.0, self.length)
        i = np.clip(np.searchsorted(self.cumulative, s, side="right") - 1, 0, len(self.points) - 2)
        u = ((s - self.cumulative[i]) / (self.cumulative[i + 1] - self.cumulative[i]))[:, None]
        pos = (1 - u) * self.points[i] + u * self.points[i + 1]
        tan = _unit((1 - u) * self.tangents[i] + u * self.tangents[i + 1])
        return pos, tan


def heading(tangents: np.ndarray) -> np.ndarray:
    """Yaw about +Z of each tangent's ground projection, unwrapped for smooth keyframes."""
    t = np.asarray(tangents, dtype=np.float64)
    return np.unwrap(np.arctan2(t[:, 1], t[:, 0]))
