"""Why an episode ends, and the collision test.

Vehicles stand on the road with yaw-only rotations, so two boxes overlap exactly when their
ground footprints do: the oriented-rectangle separating-axis test of
:mod:`symdrive_core.traffic.overlap` (touching is not a collision).
"""

from __future__ import annotations

import numpy as np

from ..traffic.overlap import footprints, frame_gaps

COLLISION = "collision"
OFF_ROAD = "off_road"
ROUTE_END = "route_end"
TIME_LIMIT = "time_limit"
INVALID_ACTION = "invalid_action"
AGENT_ERROR = "agent_error"
REASONS = (COLLISION, OFF_ROAD, ROUTE_END, TIME_LIMIT, INVALID_ACTION, AGENT_ERROR)
# Reasons that end an episode as a failure of the driving (terminated, not truncated).
TERMINAL = (COLLISION, OFF_ROAD, ROUTE_END, INVALID_ACTION, AGENT_ERROR)


def ego_footprint(x: float, y: float, yaw: float, wlh) -> np.ndarray:
    """The ego's ground rectangle [4, 2]."""
    return footprints(np.array([[x, y]]), np.array([yaw]), np.asarray(wlh, dtype=np.float64)[None])[0]


def collisions(ego_rect: np.ndarray, centres: np.ndarray, yaws: np.ndarray, wlhs: np.ndarray) -> np.ndarray:
    """Indices of the actors (centres [N, 2], yaws [N], wlhs [N, 3]) whose footprint overlaps
    the ego's ``ego_rect`` [4, 2]; also returns each one's gap to the ego (negative = overlap)."""
    if len(centres) == 0:
        return np.zeros(0, dtype=int), np.zeros(0)
    rects = np.concatenate([ego_rect[None], footprints(centres, yaws, wlhs)])
    i, j, gap = frame_gaps(rects)
    mine = i == 0
    gaps = np.empty(len(centres))
    gaps[j[mine] - 1] = gap[mine]
    return np.flatnonzero(gaps < 0), gaps
