"""The other vehicles at a moment of the episode: recorded (or keyed) poses, interpolated.

An actor is in the scene at time ``t`` when it has a pose in the frame nearest ``t``; between two
frames where it has poses it moves linearly (slerp for rotation, as
:func:`symdrive_core.scene.poses.interpolate_pose`). After the last frame every actor keeps its
last pose (a recorded drive is over; parked cars stay parked).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene.poses import Pose, interpolate_pose, yaw_of


@dataclass
class ActorState:
    id: str
    pose: Pose  # box centre and rotation in the world
    wlh: np.ndarray  # (width, length, height)
    velocity: np.ndarray  # [2] world m/s
    asset: str | None = None  # the package actor whose splats it wears (None: its own id)

    @property
    def xy(self) -> np.ndarray:
        return self.pose.translation[:2]

    @property
    def yaw(self) -> float:
        return yaw_of(self.pose.rotation)


class ReplayTraffic:
    """Actors of a manifest on their recorded poses."""

    reactive = False

    def __init__(self, manifest, default_wlh):
        self.actors = manifest.actors
        self.times = np.array([f.timestamp for f in manifest.frames], dtype=np.float64)
        self.default_wlh = np.asarray(default_wlh, dtype=np.float64)

    def reset(self, seed: int | None = None) -> None:
        pass

    def close(self) -> None:
        pass

    def _pose(self, actor, t: float) -> Pose | None:
        times = self.times
        if len(times) == 1 or t <= times[0]:
            return actor.poses[0]
        if t >= times[-1]:
            return actor.poses[-1]
        i = int(np.searchsorted(times, t, side="right")) - 1
        a, b = actor.poses[i], actor.poses[i + 1]
        if a is not None and b is not None:
            return interpolate_pose(times[i:i + 2], [a, b], t)
        u = (t - times[i]) / (times[i + 1] - times[i])
        return a if u < 0.5 else b

    def states(self, t: float, dt: float = 0.1) -> list[ActorState]:
        out = []
        for a in self.actors:
            p = self._pose(a, t)
            if p is None:
                continue
            q = self._pose(a, t + dt)
            vel = np.zeros(2) if q is None else (q.translation[:2] - p.translation[:2]) / dt
            wlh = self.default_wlh if a.wlh is None else np.asarray(a.wlh, dtype=np.float64)
            out.append(ActorState(a.id, p, wlh, vel))
        return out

    def step(self, t: float, ego) -> None:
        """Advance to time ``t`` (nothing to do: poses are a function of time)."""
