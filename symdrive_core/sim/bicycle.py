"""Kinematic bicycle model of the ego, referenced at the rear axle, integrated exactly per step.

State (x, y, yaw, v); action (acceleration a, front-wheel steering delta). With the rear axle as
reference: x' = v cos(yaw), y' = v sin(yaw), yaw' = v tan(delta) / L, v' = a. Over one step the
acceleration is constant and the speed is clamped to [0, v_max]; position and heading are
integrated in closed form along the circular arc of the step's mean speed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class EgoState:
    x: float  # box centre, world metres
    y: float
    yaw: float  # rad, heading of the vehicle's +X in the world
    v: float  # m/s, along the heading (>= 0)
    accel: float = 0.0  # applied in the last step
    steer: float = 0.0

    @property
    def xy(self) -> np.ndarray:
        return np.array([self.x, self.y])


def step(state: EgoState, accel: float, steer: float, dt: float, wheelbase: float,
         v_max: float = np.inf) -> EgoState:
    """One step of the model. The state's (x, y) is the box centre: it is moved to the rear axle
    (half the wheelbase behind), integrated, and moved back."""
    half = 0.5 * wheelbase
    rx, ry = state.x - half * np.cos(state.yaw), state.y - half * np.sin(state.yaw)
    v1 = float(np.clip(state.v + accel * dt, 0.0, v_max))
    a_eff = (v1 - state.v) / dt  # what the clamp let through
    # Exact distance: constant acceleration until the speed reaches its clamp, then constant.
    t_c = dt if accel == 0 or v1 == state.v + accel * dt else (v1 - state.v) / accel
    dist = 0.5 * (state.v + v1) * t_c + v1 * (dt - t_c)
    kappa = np.tan(steer) / wheelbase
    dyaw = dist * kappa
    if abs(dyaw) < 1e-9:
        dx, dy = dist * np.cos(state.yaw), dist * np.sin(state.yaw)
    else:
        r = 1.0 / kappa
        dx = r * (np.sin(state.yaw + dyaw) - np.sin(state.yaw))
        dy = -r * (np.cos(state.yaw + dyaw) - np.cos(state.yaw))
    yaw = float(np.arctan2(np.sin(state.yaw + dyaw), np.cos(state.yaw + dyaw)))
    rx, ry = rx + dx, ry + dy
    return EgoState(float(rx + half * np.cos(yaw)), float(ry + half * np.sin(yaw)), yaw, v1, float(a_eff),
                    float(steer))


def pure_pursuit_steer(x, y, yaw, target_xy, wheelbase: float) -> float:
    """Front-wheel angle that puts the rear axle on the circle through ``target_xy`` (pure
    pursuit, Coulter 1992); (x, y) is the box centre, the rear axle half the wheelbase behind."""
    rx, ry = x - 0.5 * wheelbase * np.cos(yaw), y - 0.5 * wheelbase * np.sin(yaw)
    dx, dy = target_xy[0] - rx, target_xy[1] - ry
    alpha = np.arctan2(dy, dx) - yaw
    ld = max(np.hypot(dx, dy), 1e-3)
    return float(np.arctan2(2.0 * wheelbase * np.sin(alpha), ld))


def ego_to_world(state: EgoState, point) -> np.ndarray:
    """A point in the ego frame (x forward, y left, metres from the box centre) -> world xy."""
    c, s = np.cos(state.yaw), np.sin(state.yaw)
    px, py = float(point[0]), float(point[1])
    return np.array([state.x + c * px - s * py, state.y + s * px + c * py])


def world_to_ego(state: EgoState, xy) -> np.ndarray:
    """World xy -> the ego frame (x forward, y left, metres from the box centre)."""
    c, s = np.cos(state.yaw), np.sin(state.yaw)
    dx, dy = float(xy[0]) - state.x, float(xy[1]) - state.y
    return np.array([c * dx + s * dy, -s * dx + c * dy])


def waypoint_control(state: EgoState, target_ego, v_target: float, wheelbase: float, speed_gain: float,
                     limits) -> tuple[float, float]:
    """The low-level controller of the waypoint action: pure pursuit to ``target_ego`` (ego frame)
    for the steering, ``speed_gain * (v_target - v)`` for the acceleration, both clipped to
    ``limits`` = ((accel lo, hi), (steer lo, hi))."""
    (alo, ahi), (slo, shi) = limits
    steer = pure_pursuit_steer(state.x, state.y, state.yaw, ego_to_world(state, target_ego), wheelbase)
    accel = speed_gain * (v_target - state.v)
    return float(np.clip(accel, alo, ahi)), float(np.clip(steer, slo, shi))
