"""Bends: the route's curvature, and the IDM agent slowing for a bend of a drive without road
truth (as an imported drive is)."""

import json

import numpy as np
import pytest

from symdrive_core import conventions
from symdrive_core.sim import SimConfig, SymDriveEnv
from symdrive_core.sim.agents import IDMAgent
from symdrive_core.sim.road import Route
from symdrive_core.sim.runner import run_episode
from symdrive_core.sim.scores import COMFORT

from ..conftest import look_at_c2w

RADIUS = 12.0
BEFORE = 60.0  # metres of straight before the bend: room to slow down comfortably from 10 m/s


def bend(before: float = BEFORE, after: float = 20.0, radius: float = RADIUS, step: float = 1.0) -> np.ndarray:
    """Points every ``step`` metres: ``before`` along +X, a 90-degree left bend, ``after`` along +Y."""
    arc = 0.5 * np.pi * radius
    s = np.arange(0.0, before + arc + after + 1e-9, step)
    xy = np.zeros((len(s), 2))
    first, middle, last = s <= before, (s > before) & (s <= before + arc), s > before + arc
    xy[first] = np.stack([s[first], np.zeros(first.sum())], axis=1)
    phi = (s[middle] - before) / radius
    xy[middle] = np.stack([before + radius * np.sin(phi), radius * (1 - np.cos(phi))], axis=1)
    xy[last] = np.stack([np.full(last.sum(), before + radius), radius + s[last] - before - arc], axis=1)
    return xy


@pytest.fixture
def bend_package(make_package):
    """A drive through the bend at 10 m/s (10 frames/s), no road truth, no actors."""
    xy = bend()
    path = make_package(n_frames=len(xy), actors=())
    data = json.loads(path.read_text())
    heading = np.gradient(xy, axis=0)
    K = data["cameras"][0]["frames"][0]["K"]
    frames = []
    for p, h in zip(xy, heading):
        c2w = look_at_c2w((p[0], p[1], 1.5), (p[0] + 10 * h[0], p[1] + 10 * h[1], 1.0))
        frames.append({"K": K, "camera_to_world": c2w.tolist(), "world_to_camera": conventions.invert_rigid(c2w).tolist()})
    data["cameras"][0]["frames"] = frames
    path.write_text(json.dumps(data))
    return path


def test_curvature_of_a_circle_and_a_line():
    route = Route.from_path(bend(step=0.25))
    arc_middle = BEFORE + 0.25 * np.pi * RADIUS
    assert route.curvature(arc_middle, 5.0) == pytest.approx(1.0 / RADIUS, rel=1e-3)
    assert route.curvature(5.0, 5.0) == pytest.approx(0.0, abs=1e-12)
    s = np.linspace(-3.0, route.length + 3.0, 41)  # past both ends too
    assert np.array_equal(route.curvature(s, 5.0), [route.curvature(u, 5.0) for u in s])
    assert np.array_equal(route.point_at(s, 1.5), [route.point_at(u, 1.5) for u in s])
    # A jittered recording of the same bend: the chord averages the jitter out.
    noisy = bend(step=0.25) + np.random.default_rng(0).normal(scale=0.02, size=(len(bend(step=0.25)), 2))
    assert Route.from_path(noisy).curvature(arc_middle, 5.0) == pytest.approx(1.0 / RADIUS, rel=0.1)


def test_idm_slows_for_the_bend(bend_package):
    env = SymDriveEnv(bend_package, SimConfig(render=False))
    assert env.area.road is None and env.recorded_speed.max() == pytest.approx(10.0, rel=0.01)
    rec = run_episode(env, IDMAgent, seed=0)
    assert rec["end_reason"] == "route_end" and rec["scores"]["drivable_area_compliance"] == 1.0
    # 10 m/s on a 12 m radius would be 8.3 m/s^2 sideways; nuPlan's comfort bound is 4.89.
    lateral = rec["scores"]["comfort_values"]["max_abs_lat_accel"]
    assert lateral < COMFORT["max_abs_lat_accel"], lateral
    v = np.array([h["v"] for h in env.history])
    s = np.array([h["progress"] for h in env.history])
    in_bend = (s > BEFORE) & (s < BEFORE + 0.5 * np.pi * RADIUS)
    assert v[in_bend].max() ** 2 / RADIUS < 1.5 * IDMAgent.a_lat
    assert v[s < 5.0].max() > 9.0  # full speed before the bend
