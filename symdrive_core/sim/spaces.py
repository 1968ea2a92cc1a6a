"""The environment's action and observation spaces, and what counts as a valid action.

An action is valid exactly when the action space contains it: the check casts it to the space's
dtype (float32) and compares there, so ``action_space.high``, ``.low`` and every sample are
accepted (``float32(0.6)`` is 2.4e-8 above 0.6; compared in float64 it would be refused). The
accepted value is then clipped to the float64 limits of :class:`.config.SimConfig`, so the
bicycle model never sees more than its limits.

With ``normalized_actions`` every entry lies in [-1, 1] (a speed in [0, 1]), as Gymnasium and
Stable-Baselines3 recommend: acceleration ``u`` means ``u * max_accel`` for ``u >= 0`` and
``u * max_brake`` below (0 coasts), steering ``u * max_steer``, waypoint x and y ``u *
waypoint_reach_m``, speed ``u * max_speed``.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from .config import SimConfig

NAMES = {"accel_steer": ("acceleration", "steering"), "waypoint": ("x", "y", "speed")}


def physical_bounds(cfg: SimConfig) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) float64 of the action in physical units (m/s^2, rad; or m, m, m/s)."""
    if cfg.action == "accel_steer":
        return np.array([-cfg.max_brake, -cfg.max_steer]), np.array([cfg.max_accel, cfg.max_steer])
    if cfg.action == "waypoint":
        r = cfg.waypoint_reach_m
        return np.array([-r, -r, 0.0]), np.array([r, r, cfg.max_speed])
    raise ValueError(f"action: expected 'accel_steer' or 'waypoint', got {cfg.action!r}")


def action_space(cfg: SimConfig) -> spaces.Box:
    lo, hi = physical_bounds(cfg)
    if cfg.normalized_actions:
        lo, hi = np.where(lo < 0, -1.0, 0.0), np.ones_like(hi)
    return spaces.Box(lo.astype(np.float32), hi.astype(np.float32), dtype=np.float32)


def _scale(cfg: SimConfig, u: np.ndarray) -> np.ndarray:
    """Physical units per normalized unit, entry by entry, for the sign of each entry of ``u``."""
    lo, hi = physical_bounds(cfg)
    return np.where(u < 0, -lo, hi)


def to_physical(action: np.ndarray, cfg: SimConfig) -> np.ndarray:
    """A valid action (float64) -> physical units, clipped to the float64 limits."""
    a = np.asarray(action, dtype=np.float64)
    if cfg.normalized_actions:
        a = a * _scale(cfg, a)
    return np.clip(a, *physical_bounds(cfg))


def from_physical(action, cfg: SimConfig) -> np.ndarray:
    """Physical units -> the action the environment takes (clipped into the space)."""
    lo, hi = physical_bounds(cfg)
    a = np.clip(np.asarray(action, dtype=np.float64), lo, hi)
    return a / _scale(cfg, a) if cfg.normalized_actions else a


def check_action(action, space: spaces.Box, names: tuple[str, ...]) -> str | None:
    """None when ``space`` contains ``action``; else what is wrong with it, in words."""
    try:
        raw = np.asarray(action)
    except (TypeError, ValueError):
        return f"not {len(names)} numbers: {action!r}"
    if raw.dtype.kind not in "biuf":  # as the space has it: objects and strings are no numbers
        return f"not {len(names)} numbers: {action!r}"
    a = raw.astype(np.float64)
    if a.shape != space.shape:
        return f"expected [{', '.join(names)}] (shape {list(space.shape)}), got shape {list(a.shape)}"
    if not np.all(np.isfinite(a)):
        return f"not finite: {a.tolist()}"
    with np.errstate(over="ignore"):  # 1e300 becomes inf in float32 and is refused below
        cast = a.astype(space.dtype)
    for v, c, lo, hi, name in zip(a, cast, space.low, space.high, names):
        if not lo <= c <= hi:
            return f"{name} {v:g} outside [{lo:g}, {hi:g}]"
    return None


def state_space(route_length: float, lanes: int, lane_offset_bound: float, cfg: SimConfig) -> spaces.Box:
    """Bounds of ``[speed, heading, heading to the route, lane offset, lane, progress]``. The lane
    index's upper bound is at least 1: a one-lane road would otherwise give equal bounds, which
    Gymnasium's checker takes for a mistake."""
    lo = [0.0, -np.pi, -np.pi, -lane_offset_bound, 0.0, 0.0]
    hi = [cfg.max_speed, np.pi, np.pi, lane_offset_bound, max(lanes - 1, 1), route_length]
    return spaces.Box(np.array(lo, dtype=np.float32), np.array(hi, dtype=np.float32), dtype=np.float32)
