"""The road traffic drives on: a centre line in the scene's world frame plus its lanes.

A package describes its road in ``manifest.ground_truth["road"]``::

    {"centerline": [[x, y, z], ...],   # metres, world frame, ordered in the driving direction
     "lanes": 2,                        # lanes across the whole road, centred on the centre line
     "lane_width": 3.5,                 # metres (default 3.5)
     "oncoming": 0}                     # how many of the lanes (the leftmost) carry traffic
                                        # against the centre line's direction (default 0)

With ``oncoming > 0`` traffic keeps right: forward lanes lie right of the oncoming ones.
Without a road in the package, a description string gives one starting at the origin along +X:
``straight:LENGTH`` or ``curved:LENGTH:RADIUS`` (a circular arc curving left; a negative radius
curves right). numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

DEFAULT_LANE_WIDTH = 3.5
ARC_STEP_M = 2.0  # spacing of the points that describe a curved road


@dataclass(frozen=True)
class Road:
    centerline: np.ndarray  # [N, 3] metres, world frame, N >= 2
    lanes: int
    lane_width: float = DEFAULT_LANE_WIDTH
    oncoming: int = 0

    @property
    def forward_lanes(self) -> int:
        return self.lanes - self.oncoming

    @property
    def length(self) -> float:
        return float(arc_lengths(self.centerline[:, :2])[-1])

    def lane_offset(self, forward: bool) -> float:
        """Lateral offset (positive = left of the centre line) of one direction's lanes' middle."""
        half_road = 0.5 * self.lanes * self.lane_width
        if forward:
            return -half_road + 0.5 * self.forward_lanes * self.lane_width
        return half_road - 0.5 * self.oncoming * self.lane_width

    def to_json(self) -> dict:
        return {"centerline": np.round(self.centerline, 6).tolist(), "lanes": self.lanes,
                "lane_width": self.lane_width, "oncoming": self.oncoming}

    def ground_height(self, xy: np.ndarray) -> np.ndarray:
        """Road surface height under points ``xy`` [M, 2]: the centre line's z where they project."""
        _, s_frac, seg = project_onto(self.centerline[:, :2], np.asarray(xy, dtype=np.float64))
        z = self.centerline[:, 2]
        return (1.0 - s_frac) * z[seg] + s_frac * z[seg + 1]


def road_from_json(d, source) -> Road:
    """Validate a ``ground_truth.road`` block; errors name the field."""
    where = "ground_truth.road"
    if not isinstance(d, dict):
        raise InputError(source, "expected an object", where)
    pts = d.get("centerline")
    try:
        line = np.asarray(pts, dtype=np.float64)
    except (TypeError, ValueError):
        line = np.empty((0,))
    if line.ndim != 2 or line.shape[1] != 3 or len(line) < 2 or not np.all(np.isfinite(line)):
        raise InputError(source, "expected a list of at least two [x, y, z] points", f"{where}.centerline")
    if np.any(np.linalg.norm(np.diff(line[:, :2], axis=0), axis=1) < 1e-6):
        raise InputError(source, "consecutive points must differ in x, y", f"{where}.centerline")
    lanes = d.get("lanes", 1)
    if isinstance(lanes, bool) or not isinstance(lanes, int) or lanes < 1:
        raise InputError(source, f"expected an integer >= 1, got {lanes!r}", f"{where}.lanes")
    width = d.get("lane_width", DEFAULT_LANE_WIDTH)
    if isinstance(width, bool) or not isinstance(width, (int, float)) or not width > 0:
        raise InputError(source, f"expected a positive number of metres, got {width!r}", f"{where}.lane_width")
    oncoming = d.get("oncoming", 0)
    if isinstance(oncoming, bool) or not isinstance(oncoming, int) or not 0 <= oncoming < lanes:
        raise InputError(source, f"expected an integer from 0 to lanes - 1, got {oncoming!r}", f"{where}.oncoming")
    return Road(line, lanes, float(width), oncoming)


def road_from_spec(spec: str, lanes: int = 2, lane_width: float = DEFAULT_LANE_WIDTH) -> Road:
    """``straight:LENGTH`` or ``curved:LENGTH:RADIUS`` -> a road from the origin along +X."""
    parts = spec.split(":")
    try:
        values = [float(p) for p in parts[1:]]
    except ValueError:
        values = []
    if parts[0] == "straight" and len(values) == 1 and values[0] > 0:
        line = np.array([[0.0, 0.0, 0.0], [values[0], 0.0, 0.0]])
    elif parts[0] == "curved" and len(values) == 2 and values[0] > 0 and values[1] != 0:
        line = arc_points(values[0], values[1])
    else:
        raise InputError("--road", f"expected straight:LENGTH or curved:LENGTH:RADIUS with positive length "
                                   f"and non-zero radius, got {spec!r}")
    return Road(line, lanes, lane_width)


def arc_points(length: float, radius: float) -> np.ndarray:
    """Circular arc from the origin heading +X; positive radius turns left."""
    n = max(2, int(np.ceil(length / ARC_STEP_M)) + 1)
    phi = np.linspace(0.0, length / abs(radius), n)
    sign = np.sign(radius)
    r = abs(radius)
    return np.stack([r * np.sin(phi), sign * r * (1.0 - np.cos(phi)), np.zeros(n)], axis=1)


# ---------------------------------------------------------------- polyline geometry


def arc_lengths(line_xy: np.ndarray) -> np.ndarray:
    """Distance along the polyline at each of its points, starting at 0."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line_xy, axis=0), axis=1))])


def offset_polyline(line_xy: np.ndarray, offset: float) -> np.ndarray:
    """The polyline moved sideways by ``offset`` (positive = left), along vertex normals.

    Vertex normals bisect the adjacent segments and are scaled so both segments move by exactly
    ``offset`` (a mitred offset), so lanes stay parallel through gentle bends.
    """
    d = np.diff(line_xy, axis=0)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    seg_normals = np.stack([-d[:, 1], d[:, 0]], axis=1)
    normals = np.concatenate([seg_normals[:1], seg_normals[:-1] + seg_normals[1:], seg_normals[-1:]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    seg_at_vertex = np.concatenate([seg_normals[:1], seg_normals[:-1], seg_normals[-1:]])
    cos_half = np.sum(normals * seg_at_vertex, axis=1, keepdims=True)
    return line_xy + offset * normals / np.maximum(cos_half, 0.2)


def project_onto(line_xy: np.ndarray, points: np.ndarray):
    """Nearest point on the polyline for each point: (lateral offset, fraction along, segment).

    Lateral offset is signed, positive to the left of the direction of travel.
    """
    a, b = line_xy[:-1], line_xy[1:]
    ab = b - a  # [S, 2]
    ap = points[:, None, :] - a[None]  # [M, S, 2]
    u = np.clip(np.sum(ap * ab, axis=2) / np.sum(ab * ab, axis=1), 0.0, 1.0)  # [M, S]
    closest = a[None] + u[..., None] * ab[None]
    dist = np.linalg.norm(points[:, None, :] - closest, axis=2)
    seg = np.argmin(dist, axis=1)
    rows = np.arange(len(points))
    rel = points - closest[rows, seg]
    side = np.sign(ab[seg, 0] * rel[:, 1] - ab[seg, 1] * rel[:, 0])
    return side * dist[rows, seg], u[rows, seg], seg
