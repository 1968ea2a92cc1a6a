"""Where the ego may drive and where it is going.

The drivable area is the package's road (``ground_truth.road``, read by
:func:`symdrive_core.scene.road.road_from_json`): every lane across it, centred on its centre
line. A package without a road gets a corridor ``corridor_half_width_m`` each side of the
recorded ego path instead. The route is the recorded ego path; progress is the arc length of
the ego's projection onto it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene.road import Road, arc_lengths, project_onto, road_from_json


@dataclass
class DrivableArea:
    line: np.ndarray  # [N, 2] centre line of the drivable area, world xy
    half_width: float  # metres each side of the line
    lane_width: float
    lanes: int
    road: Road | None = None  # the package's road, when it has one
    line_z: np.ndarray | None = None  # [N] ground height along the line

    def lateral(self, xy: np.ndarray) -> np.ndarray:
        """Signed lateral offsets (positive = left) of points [M, 2] from the centre line."""
        lat, _, _ = project_onto(self.line, np.atleast_2d(xy))
        return lat

    def outside(self, corners: np.ndarray, margin: float = 0.0) -> bool:
        """Whether any of the points [M, 2] lies beyond the edge (by more than ``margin``), or
        beyond either end of the line."""
        lat, u, seg = project_onto(self.line, np.atleast_2d(corners))
        beyond_end = ((seg == len(self.line) - 2) & (u >= 1.0)) | ((seg == 0) & (u <= 0.0))
        return bool(np.any(np.abs(lat) > self.half_width + margin) or np.any(beyond_end))

    def lane_position(self, xy) -> tuple[int, float]:
        """(lane index from the right edge, offset from that lane's middle, positive = left)."""
        lat = float(self.lateral(np.asarray(xy, dtype=np.float64)[None])[0])
        from_right = lat + self.half_width
        k = int(np.clip(np.floor(from_right / self.lane_width), 0, self.lanes - 1))
        return k, from_right - (k + 0.5) * self.lane_width

    def lane_center_offset(self, k: int) -> float:
        """Lateral offset (positive = left) of lane ``k``'s middle from the centre line."""
        return -self.half_width + (k + 0.5) * self.lane_width

    def summary(self) -> dict:
        """What the episode's road was, for the report: the package's or the corridor."""
        return {"source": "ground_truth.road" if self.road is not None else "corridor", "lanes": self.lanes,
                "lane_width_m": self.lane_width, "half_width_m": self.half_width}

    def ground(self, xy: np.ndarray) -> np.ndarray:
        if self.road is not None:
            return self.road.ground_height(np.atleast_2d(xy))
        _, u, seg = project_onto(self.line, np.atleast_2d(xy))
        return (1.0 - u) * self.line_z[seg] + u * self.line_z[seg + 1]


def drivable_area(ground_truth: dict, source, path_xy: np.ndarray, path_ground_z: np.ndarray,
                  corridor_half_width: float) -> DrivableArea:
    """The package's road if it has one, else a corridor around ``path_xy``."""
    if "road" in ground_truth:
        road = road_from_json(ground_truth["road"], source)
        return DrivableArea(road.centerline[:, :2].copy(), 0.5 * road.lanes * road.lane_width, road.lane_width,
                            road.lanes, road, road.centerline[:, 2].copy())
    line, z = dedupe(path_xy, path_ground_z)
    # Extend the corridor half a car beyond both ends so the start pose lies inside it.
    d0 = (line[1] - line[0]) / np.linalg.norm(line[1] - line[0])
    d1 = (line[-1] - line[-2]) / np.linalg.norm(line[-1] - line[-2])
    line = np.concatenate([[line[0] - 5.0 * d0], line, [line[-1] + 5.0 * d1]])
    z = np.concatenate([[z[0]], z, [z[-1]]])
    width = 2.0 * corridor_half_width
    return DrivableArea(line, corridor_half_width, width, 1, None, z)


def dedupe(xy: np.ndarray, z: np.ndarray | None = None, min_step: float = 1e-3):
    """Drop points closer than ``min_step`` to the previous kept one (a standing recording)."""
    keep = [0]
    for i in range(1, len(xy)):
        if np.linalg.norm(xy[i] - xy[keep[-1]]) >= min_step:
            keep.append(i)
    if len(keep) < 2:  # the recording never moves: a 1 m stub along +X
        xy = np.array([xy[0], xy[0] + [1.0, 0.0]])
        return xy, (np.array([z[0], z[0]]) if z is not None else None)
    return xy[keep], (z[keep] if z is not None else None)


@dataclass
class Route:
    """The recorded ego path as a polyline with arc lengths."""

    xy: np.ndarray  # [N, 2]
    s: np.ndarray  # [N]

    @classmethod
    def from_path(cls, xy: np.ndarray) -> Route:
        xy, _ = dedupe(np.asarray(xy, dtype=np.float64))
        return cls(xy, arc_lengths(xy))

    @property
    def length(self) -> float:
        return float(self.s[-1])

    def progress(self, xy) -> float:
        """Arc length of the nearest point of the route to ``xy``."""
        _, u, seg = project_onto(self.xy, np.asarray(xy, dtype=np.float64)[None])
        return float(self.s[seg[0]] + u[0] * (self.s[seg[0] + 1] - self.s[seg[0]]))

    def point_at(self, s, lateral: float = 0.0) -> np.ndarray:
        """The point ``s`` metres along the route (extended straight past its ends), moved
        ``lateral`` metres to the left: [2] for a number, [N, 2] for N arc lengths."""
        u = np.asarray(s, dtype=np.float64)
        i = np.clip(np.searchsorted(self.s, u) - 1, 0, len(self.s) - 2)
        d = self.xy[i + 1] - self.xy[i]
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        p = self.xy[i] + (u - self.s[i])[..., None] * d
        return p + lateral * np.stack([-d[..., 1], d[..., 0]], axis=-1)

    def curvature(self, s, chord: float):
        """Unsigned curvature (1/m) at ``s`` (a number or an array): the turn between the chords
        ``chord`` metres before and after, over ``chord``. Exact on a circle (equal arcs turn
        their chords by the arc's angle), and the chord averages out a recorded path's jitter."""
        u = np.asarray(s, dtype=np.float64)
        a, b, c = self.point_at(u - chord), self.point_at(u), self.point_at(u + chord)
        h1 = np.arctan2(b[..., 1] - a[..., 1], b[..., 0] - a[..., 0])
        h2 = np.arctan2(c[..., 1] - b[..., 1], c[..., 0] - b[..., 0])
        k = np.abs(np.arctan2(np.sin(h2 - h1), np.cos(h2 - h1))) / chord
        return float(k) if k.ndim == 0 else k

    def heading_at(self, s: float) -> float:
        i = int(np.clip(np.searchsorted(self.s, s) - 1, 0, len(self.s) - 2))
        d = self.xy[i + 1] - self.xy[i]
        return float(np.arctan2(d[1], d[0]))
