"""Closed-loop scores of one episode, as NAVSIM's PDM score defines them.

Definition (Dauner et al., "NAVSIM: Data-Driven Non-Reactive Autonomous Vehicle Simulation and
Benchmarking", NeurIPS 2024 Datasets and Benchmarks, arXiv:2406.15349, section 3, "PDM Score";
the sub-metrics are nuPlan's closed-loop metrics):

    PDMS = NC x DAC x (5 TTC + 2 C + 5 EP) / 12

* NC, no collision: 1, or 0 once the ego's box overlaps another vehicle's (NAVSIM counts only
  at-fault collisions and weighs collisions with static objects 0.5; every actor here is a
  vehicle and no fault is attributed, so any collision scores 0).
* DAC, drivable-area compliance: 1, or 0 once a corner of the ego's box leaves the road.
* TTC, time to collision: 1, or 0 when at some step the ego, driving on at constant speed and
  heading, would overlap a vehicle moving on at its current velocity within 1 s, looked at every
  0.1 s whatever the step (a standing ego is not counted).
* C, comfort: 1 when the ego's motion stays within nuPlan's comfort bounds (longitudinal
  acceleration in [-4.05, 2.40] m/s^2, |lateral acceleration| <= 4.89 m/s^2, |longitudinal jerk|
  <= 4.13 m/s^3, |jerk| <= 8.37 m/s^3, |yaw rate| <= 0.95 rad/s, |yaw acceleration| <= 1.93
  rad/s^2), else 0. Derivatives are finite differences of the simulated states (no filter).
* EP, ego progress: NAVSIM divides the progress along the route by that of a reference planner
  (PDM-Closed); here the reference is the recorded drive, so EP is route completion, the
  fraction of the route's length driven, clipped to [0, 1].
"""

from __future__ import annotations

import numpy as np

from . import episode as ep

COMFORT = {"min_lon_accel": -4.05, "max_lon_accel": 2.40, "max_abs_lat_accel": 4.89,
           "max_abs_lon_jerk": 4.13, "max_abs_jerk": 8.37, "max_abs_yaw_rate": 0.95,
           "max_abs_yaw_accel": 1.93}
TTC_THRESHOLD_S = 1.0
WEIGHTS = {"ttc": 5.0, "comfort": 2.0, "route_completion": 5.0}


def _d(x: np.ndarray, dt: float) -> np.ndarray:
    return np.diff(x) / dt if len(x) > 1 else np.zeros(0)


def comfort_values(history: list[dict], dt: float) -> dict:
    """Extremes of the ego's motion over the episode (finite differences)."""
    v = np.array([h["v"] for h in history])
    yaw = np.unwrap(np.array([h["yaw"] for h in history]))
    xy = np.array([[h["x"], h["y"]] for h in history])
    lon = _d(v, dt)
    yaw_rate = _d(yaw, dt)
    lat = v[1:] * yaw_rate if len(v) > 1 else np.zeros(0)
    vel = np.diff(xy, axis=0) / dt if len(xy) > 1 else np.zeros((0, 2))
    acc = np.diff(vel, axis=0) / dt if len(vel) > 1 else np.zeros((0, 2))
    jerk = np.linalg.norm(np.diff(acc, axis=0), axis=1) / dt if len(acc) > 1 else np.zeros(0)

    def ext(x, f):
        return float(f(x)) if len(x) else 0.0

    return {"min_lon_accel": ext(lon, np.min), "max_lon_accel": ext(lon, np.max),
            "max_abs_lat_accel": ext(np.abs(lat), np.max), "max_abs_lon_jerk": ext(np.abs(_d(lon, dt)), np.max),
            "max_abs_jerk": ext(jerk, np.max), "max_abs_yaw_rate": ext(np.abs(yaw_rate), np.max),
            "max_abs_yaw_accel": ext(np.abs(_d(yaw_rate, dt)), np.max)}


def comfortable(values: dict) -> bool:
    return all(values[k] >= b if k.startswith("min") else values[k] <= b for k, b in COMFORT.items())


def score_episode(history: list[dict], dt: float, goal: float, end_reason: str | None) -> dict:
    """Every sub-score, the combined PDM score and the measurements behind them. ``goal``: the
    progress along the route at which the episode ends as driven to its end (route completion 1).
    An episode its agent ended (an error, an action outside the space) drove nothing it chose to:
    PDM score 0."""
    values = comfort_values(history, dt)
    ttcs = [h["ttc"] for h in history if h.get("ttc") is not None]
    min_ttc = min(ttcs) if ttcs else None
    progress = max(h["progress"] for h in history) - history[0]["progress"]
    to_go = goal - history[0]["progress"]
    s = {
        "no_collision": 0.0 if end_reason == ep.COLLISION else 1.0,
        "drivable_area_compliance": 0.0 if end_reason == ep.OFF_ROAD else 1.0,
        "ttc": 0.0 if (min_ttc is not None and min_ttc < TTC_THRESHOLD_S) else 1.0,
        "comfort": 1.0 if comfortable(values) else 0.0,
        "route_completion": float(np.clip(progress / to_go, 0.0, 1.0)) if to_go > 0 else 1.0,
    }
    weighted = (WEIGHTS["ttc"] * s["ttc"] + WEIGHTS["comfort"] * s["comfort"]
                + WEIGHTS["route_completion"] * s["route_completion"]) / sum(WEIGHTS.values())
    failed = end_reason in (ep.AGENT_ERROR, ep.INVALID_ACTION)
    s["pdm_score"] = 0.0 if failed else s["no_collision"] * s["drivable_area_compliance"] * weighted
    s["min_ttc_s"] = min_ttc
    s["progress_m"] = float(progress)
    s["comfort_values"] = values
    return s
