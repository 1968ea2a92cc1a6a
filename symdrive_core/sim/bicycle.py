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
