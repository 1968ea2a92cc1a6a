"""Moving traffic of the built-in street: vehicles that drive while the ego records.

A plan is arithmetic on the street's curve, deterministic per seed. Each vehicle moves at its own
constant speed along the road's x (the measure the ego's timestamps use: frame i is at
``i * spacing / SPEED``), at a lateral offset from the centreline that is constant except for the
one lane changer; its yaw follows its motion. Roles, by index k:

    lead       the ego's lane, ahead of it, near the ego's speed (k = 0, 4, 6, ...)
    oncoming   the other lane, towards the ego; the first passes it during the drive where the
               road leaves room (k = 1, 3, 5, ...)
    overtaker  ahead of the leads in the other lane, faster, changing into the ego's lane early in
               the drive, before the oncoming cars reach it (k = 2)

Each vehicle is drawn again until it shares road space with none placed before it (the ego
included) at any moment of the drive. In Blender each vehicle is a ``build_car`` mesh with its
own object pass index, posed before every render as at the render's frame (lateral and insertion
views included: a camera shifted into the other lane can meet an oncoming car). Its poses are the
manifest's existing actors (3DRealCar frame: origin at the box centre, half the car's height
above the road).
"""

from __future__ import annotations

from dataclasses import dataclass

import bpy
import numpy as np

from symdrive_core import conventions
from symdrive_core.rotations import quat_from_yaw
from symdrive_core.scene import Pose

from .insertion import place_object
from .street import LANE_WIDTH, X_END, X_START, Street
from .vehicles import TRAFFIC_PRESETS, build_car

TRAFFIC_INDEX = 2  # object pass index of car 0 (car k: TRAFFIC_INDEX + k); 1 is the inserted vehicle
EGO_LANE, OTHER_LANE = -LANE_WIDTH / 2, LANE_WIDTH / 2  # lane centres, metres left of the centreline
# Linear RGB, hues that no parked car or asset has: a moving car is told apart at a glance.
PAINTS = [(0.7, 0.03, 0.35), (0.02, 0.35, 0.38), (0.45, 0.7, 0.02), (0.3, 0.6, 0.85),
          (0.3, 0.05, 0.45), (0.05, 0.6, 0.45), (0.85, 0.4, 0.55), (0.9, 0.75, 0.02)]
GAP_M = 7.0  # least centre distance along the road between two vehicles in the same lane
SAME_LANE_M = 2.5  # lateral distance under which two vehicles share a lane
TRIES = 500
EDIT_KINDS = ("remove", "move", "retime")
RETIME_S = 0.5
_DT = 1e-3  # seconds either side for the direction of motion


@dataclass(frozen=True)
class Vehicle:
    role: str
    kind: str  # a TRAFFIC_PRESETS key
    paint: tuple[float, float, float]
    x0: float  # road x at t = 0
    speed: float  # metres of road x per second
    direction: int  # +1 with the ego, -1 towards it
    lateral0: float  # metres left of the centreline, before the lane change
    lateral1: float  # after it (= lateral0 for a vehicle that keeps its lane)
    change_start: float = 0.0  # seconds
    change_seconds: float = 1.0

    def x(self, t):
        return self.x0 + self.direction * self.speed * np.asarray(t, dtype=np.float64)

    def at(self, t) -> np.ndarray:
        """(road x, lateral) [..., 2] at the times ``t``."""
        return np.stack([self.x(t), self.lateral(t)], -1)

    def lateral(self, t):
        """Smoothstep between the lanes: no jump in position or heading."""
        u = np.clip((np.asarray(t, dtype=np.float64) - self.change_start) / self.change_seconds, 0.0, 1.0)
        return self.lateral0 + (self.lateral1 - self.lateral0) * u * u * (3.0 - 2.0 * u)

    def on_street(self, t) -> bool:
        return bool(X_START <= self.x(t) <= X_END)

    def ground(self, street: Street, t: float) -> tuple[np.ndarray, float]:
        """Road point under the vehicle at ``t`` and its yaw (direction of motion)."""
        p, _ = street.frame_at(self.x(t), self.lateral(t))
        a, _ = street.frame_at(self.x(t - _DT), self.lateral(t - _DT))
        b, _ = street.frame_at(self.x(t + _DT), self.lateral(t + _DT))
        return p, float(np.arctan2(b[1] - a[1], b[0] - a[0]))

    def pose(self, street: Street, t: float, wlh) -> Pose | None:
        """The 3DRealCar pose at ``t``; None while the vehicle is beyond the street's ends."""
        if not self.on_street(t):
            return None
        p, yaw = self.ground(street, t)
        return Pose(np.array([p[0], p[1], conventions.vehicle_ground_offset(wlh)]), quat_from_yaw(yaw))


def roles(n: int) -> list[str]:
    return ["overtaker" if k == 2 else ("lead", "oncoming")[k % 2] for k in range(n)]


def _draw(role: str, rng, duration: float, ego: Vehicle, placed: list[Vehicle], relax: float) -> dict:
    """Motion of a vehicle of ``role``, placed so that the ego sees it during the drive; ``relax``
    (0 .. 1, grows with failed draws) widens the ranges towards where the road is free."""
    v = ego.speed
    in_lane = [p for p in [ego, *placed] if p.direction > 0 and p.lateral1 == EGO_LANE]
    if role == "lead":  # ahead of every car already in the ego's lane, at both ends of the drive
        speed = v * rng.uniform(0.75, 1.15)
        back = max(max(float(p.x(0.0)), float(p.x(duration)) - speed * duration) for p in in_lane)
        gap = 12.0 + rng.uniform(0.0, 6.0) if len(in_lane) == 1 else GAP_M + rng.uniform(2.0, 14.0)
        return dict(x0=back + gap, speed=speed, direction=1, lateral0=EGO_LANE, lateral1=EGO_LANE)
    if role == "oncoming":
        speed = v * rng.uniform(0.8, 1.4)
        later = 1.5 * sum(p.role == role for p in placed)  # the first passes the ego during the drive
        meet = rng.uniform(0.25 * duration, (1.0 + relax) * duration + later + relax)  # when it passes the ego
        return dict(x0=ego.x0 + (v + speed) * meet, speed=speed, direction=-1, lateral0=OTHER_LANE,
                    lateral1=OTHER_LANE)
    change = float(np.clip(0.4 * duration, 1.0, 2.0))  # early: the other lane is free for oncoming cars
    x0 = max(float(p.x(0.0)) for p in in_lane) + rng.uniform(8.0, 30.0 + 30.0 * relax)  # ahead of the leads
    return dict(x0=x0, speed=v * rng.uniform(1.2, 1.45), direction=1, lateral0=OTHER_LANE, lateral1=EGO_LANE,
                change_start=rng.uniform(-0.3 * change, 0.3 * duration), change_seconds=change)


def conflict(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether (road x, lateral) positions [..., 2] are closer than a vehicle's length in one lane."""
    return (np.abs(a[..., 0] - b[..., 0]) < GAP_M) & (np.abs(a[..., 1] - b[..., 1]) < SAME_LANE_M)


def _clear(vehicle: Vehicle, others: list[Vehicle], times) -> bool:
    """No moment of the drive where ``vehicle`` shares road space with one of ``others``."""
    return not any(np.any(conflict(vehicle.at(times), o.at(times))) for o in others)


def ego_vehicle(speed: float, x0: float = 0.0) -> Vehicle:
    return Vehicle("ego", "", (0.0, 0.0, 0.0), x0, speed, 1, EGO_LANE, EGO_LANE)


def _placing_order(rs: list[str]) -> list[int]:
    """The nearest lead, the first oncoming car, the overtaker where they leave it room, then the
    others (each fits where the road is still free)."""
    def rank(k):
        first = (rs[k] == "lead" and k == 0, rs[k] == "oncoming" and k == 1, rs[k] == "overtaker")
        return (first.index(True) if any(first) else 3, k)
    return sorted(range(len(rs)), key=rank)


def plan(n: int, seed: int, duration: float, ego: Vehicle) -> list[Vehicle]:
    """``n`` vehicles around the ego's drive of ``duration`` seconds. Each is drawn again until
    it is clear of the ego and of those placed before it. Its own random stream: the street's
    draws stay as they were."""
    rng = np.random.default_rng([seed, 0x7AFF1C])
    kinds = sorted(TRAFFIC_PRESETS)
    times = np.linspace(0.0, duration, max(2, int(np.ceil(duration / 0.05)) + 1))
    rs = roles(n)
    placed: dict[int, Vehicle] = {}
    for k in _placing_order(rs):
        for attempt in range(TRIES):
            v = Vehicle(rs[k], kinds[rng.integers(len(kinds))], PAINTS[k % len(PAINTS)],
                        **_draw(rs[k], rng, duration, ego, list(placed.values()), attempt / TRIES))
            if _clear(v, [ego, *placed.values()], times):
                placed[k] = v
                break
        else:
            raise RuntimeError(f"no clear road for traffic vehicle {k} ({rs[k]}) in {TRIES} draws (seed {seed})")
    return [placed[k] for k in range(n)]


class Traffic:
    """The plan as Blender cars: their poses per frame, and one car edited in one frame."""

    def __init__(self, street: Street, n: int, seed: int, times: list[float], ego: Vehicle):
        self.street, self.times, self.ego = street, list(times), ego
        self.vehicles = plan(n, seed, self.times[-1], ego)
        col = bpy.data.collections.new("traffic")
        bpy.context.scene.collection.children.link(col)
        self.objects = []
        for k, v in enumerate(self.vehicles):
            obj = build_car(f"car_{k}", TRAFFIC_PRESETS[v.kind], v.paint, col)
            obj.pass_index = TRAFFIC_INDEX + k
            self.objects.append(obj)
        self.poses = [[v.pose(street, t, obj["wlh"]) for t in self.times]
                      for v, obj in zip(self.vehicles, self.objects)]

    def __len__(self) -> int:
        return len(self.vehicles)

    def wlh(self, k: int) -> list[float]:
        return [float(v) for v in self.objects[k]["wlh"]]

    def show(self, frame: int, edited: dict[int, Pose | None] | None = None) -> None:
        """Pose every car as at ``frame`` (``edited``: car -> pose instead, None = removed)."""
        edited = edited or {}
        for k, obj in enumerate(self.objects):
            pose = edited.get(k, self.poses[k][frame])
            obj.hide_render = pose is None
            if pose is not None:
                place_object(obj, pose)

    def _clear_of_others(self, k: int, frame: int, at: np.ndarray) -> bool:
        """Car k at (road x, lateral) ``at`` shares road space with no other car nor the ego at ``frame``."""
        t = self.times[frame]
        others = [v for j, v in enumerate(self.vehicles) if j != k and self.poses[j][frame] is not None]
        return not any(conflict(at, v.at(t)) for v in [self.ego, *others])

    def moved(self, k: int, frame: int) -> tuple[Pose, float] | None:
        """Car k one lane width across towards the other lane, same road x and yaw, and that
        offset (metres left of the road's direction); None where it would meet another car."""
        v, t, recorded = self.vehicles[k], self.times[frame], self.poses[k][frame]
        x, lateral = v.at(t)
        offset = LANE_WIDTH if lateral < 0 else -LANE_WIDTH
        if not self._clear_of_others(k, frame, np.array([x, lateral + offset])):
            return None
        p, _ = self.street.frame_at(x, lateral + offset)
        return Pose(np.array([p[0], p[1], recorded.translation[2]]), recorded.rotation.copy()), offset

    def retimed(self, k: int, frame: int, shift_s: float = RETIME_S) -> Pose | None:
        """Car k where its own motion has it ``shift_s`` later; None beyond the street or where it
        would meet another car."""
        v, t = self.vehicles[k], self.times[frame] + shift_s
        if not self._clear_of_others(k, frame, v.at(t)):
            return None
        return v.pose(self.street, t, self.objects[k]["wlh"])
