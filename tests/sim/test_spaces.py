"""The action and observation spaces: actions at the edge of the space are valid, everything
outside is refused, observations stay inside their declared bounds, and Gymnasium's own checker
finds nothing to warn about."""

import itertools
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from symdrive_core.sim import SimConfig, SymDriveEnv
from symdrive_core.sim.spaces import NAMES, action_space, check_action, from_physical, to_physical

from .conftest import DEMO, only_actors

KINDS = [(action, normalized) for action in ("accel_steer", "waypoint") for normalized in (False, True)]


def _corners(space):
    return [np.array(c, dtype=space.dtype) for c in itertools.product(*zip(space.low, space.high))]


@pytest.mark.parametrize("action,normalized", KINDS)
def test_every_corner_of_the_space_is_a_valid_action(demo, action, normalized):
    cfg = SimConfig(render=False, action=action, normalized_actions=normalized)
    env = SymDriveEnv(only_actors(demo, set()), cfg)
    for corner in _corners(env.action_space):
        env.reset(seed=0)
        _, _, _, _, info = env.step(corner)
        assert info["end_reason"] != "invalid_action", (corner, info)
        assert env.steps == 1


def test_full_steering_is_applied_at_the_physical_limit(demo):
    """float32(0.6) is 2.4e-8 above 0.6: accepted, and the bicycle model gets exactly 0.6."""
    for normalized in (False, True):
        cfg = SimConfig(render=False, normalized_actions=normalized)
        env = SymDriveEnv(only_actors(demo, set()), cfg)
        if not normalized:
            assert float(env.action_space.high[1]) > cfg.max_steer  # the float32 bound is above the limit
        env.reset(seed=0)
        env.step(env.action_space.high)
        assert env.history[-1]["steer"] == cfg.max_steer
        env.reset(seed=0)
        env.step(env.action_space.low)
        assert env.history[-1]["steer"] == -cfg.max_steer


def test_samples_are_valid_and_the_next_float32_outside_is_not():
    for action, normalized in KINDS:
        space = action_space(SimConfig(action=action, normalized_actions=normalized))
        space.seed(0)
        names = NAMES[action]
        assert all(check_action(space.sample(), space, names) is None for _ in range(5000))
        for i in range(space.shape[0]):
            for bound, direction in ((space.high, np.inf), (space.low, -np.inf)):
                a = space.high.copy() if bound is space.high else space.low.copy()
                a[i] = np.nextafter(bound[i], np.float32(direction))
                problem = check_action(a, space, names)
                assert problem is not None and problem.startswith(names[i] + " "), problem
                assert check_action(a.astype(np.float64), space, names) == problem


@pytest.mark.parametrize("bad,why", [([np.nan, 0.0], "not finite"), ([0.0, np.inf], "not finite"),
                                     ([1e300, 0.0], "acceleration"), ([0.0], "expected"), ("fast", "not 2 numbers"),
                                     ([0.0, 0.6 + 1e-6], "steering"), (np.zeros((2, 1)), "got shape [2, 1]"),
                                     ([[0.0, 0.0]], "got shape [1, 2]"), (np.array([0.0, 0.0], object), "not 2 numbers")])
def test_actions_outside_the_space_are_refused(bad, why):
    space = action_space(SimConfig())
    problem = check_action(bad, space, NAMES["accel_steer"])
    assert problem is not None and why in problem
    assert not space.contains(np.asarray(bad) if not isinstance(bad, str) else bad)  # refused exactly as the space does


def test_normalized_actions_map_to_the_limits():
    cfg = SimConfig(normalized_actions=True)
    assert np.array_equal(to_physical([1.0, 1.0], cfg), [cfg.max_accel, cfg.max_steer])
    assert np.array_equal(to_physical([-1.0, -1.0], cfg), [-cfg.max_brake, -cfg.max_steer])
    assert np.array_equal(to_physical([0.0, 0.0], cfg), [0.0, 0.0])
    assert np.allclose(to_physical([-0.5, 0.25], cfg), [-0.5 * cfg.max_brake, 0.25 * cfg.max_steer], rtol=0, atol=1e-15)
    way = SimConfig(action="waypoint", normalized_actions=True)
    assert np.allclose(to_physical([0.1, -0.2, 0.5], way),
                       [0.1 * way.waypoint_reach_m, -0.2 * way.waypoint_reach_m, 0.5 * way.max_speed])
    rng = np.random.default_rng(0)
    for c in (cfg, way):
        space = action_space(c)
        u = rng.uniform(space.low, space.high, size=(200, space.shape[0]))
        back = np.array([from_physical(to_physical(x, c), c) for x in u])
        assert np.allclose(back, u, rtol=0, atol=1e-12)
    # Physical commands beyond the limits are clipped into the space.
    assert np.array_equal(from_physical([100.0, -3.0], cfg), [1.0, -1.0])


def test_observations_stay_inside_their_bounds_when_leaving_the_road(demo):
    """Long steps, full brake, full right: the last step ends far beyond the road's edge, where
    the lane offset is clipped to its bound."""
    env = SymDriveEnv(only_actors(demo, set()), SimConfig(render=False, dt=2.0))
    space = env.observation_space
    obs, _ = env.reset(seed=0)
    assert space.contains(obs)
    while env.end_reason is None:
        obs, *_ = env.step(env.action_space.low)
        assert space.contains(obs), (obs, space["state"])
    assert env.end_reason == "off_road"
    assert env.history[-1]["lane_offset"] < -env.lane_offset_bound
    assert obs["state"][3] == np.float32(-env.lane_offset_bound)


def test_start_faster_than_the_limit_is_clamped(demo):
    cfg = SimConfig(render=False, max_speed=1.0)
    env = SymDriveEnv(demo, cfg)
    assert env.recorded_speed[0] > cfg.max_speed
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs) and obs["state"][0] == cfg.max_speed


def _warnings_of_check_env(config: SimConfig) -> list[str]:
    env = gym.make("SymDrive-v0", package=DEMO, config=config)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    env.close()
    return [str(w.message) for w in caught]


@pytest.mark.parametrize("action", ["accel_steer", "waypoint"])
def test_check_env_passes_without_a_warning(action):
    """Rendered at a tiny size (the render-mode check makes a second environment)."""
    cfg = SimConfig(action=action, normalized_actions=True, image_size=(16, 9))
    assert _warnings_of_check_env(cfg) == []


def test_check_env_in_physical_units_only_recommends_normalizing():
    messages = _warnings_of_check_env(SimConfig(render=False))
    assert len(messages) == 1 and "normalized" in messages[0]


def test_render_follows_the_render_mode(demo):
    env = SymDriveEnv(demo, SimConfig(render=False, image_size=(16, 9)))
    env.reset(seed=0)
    assert env.render() is None
    env = gym.make("SymDrive-v0", package=demo, config=SimConfig(render=False, image_size=(16, 9)),
                   render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (9, 16, 3) and frame.dtype == np.uint8 and frame.std() > 5
    assert env.metadata["render_fps"] == pytest.approx(1.0 / env.unwrapped.dt)
    with pytest.raises(ValueError, match="render_mode"):
        SymDriveEnv(demo, SimConfig(render=False), render_mode="human")


def test_gymnasium_finds_the_environment_in_a_fresh_process():
    """Both spellings work without touching SymDriveEnv first: the id after importing the
    package, and the module-prefixed id that makes Gymnasium import it."""
    import subprocess
    import sys

    code = ("import gymnasium as gym\n"
            "import {module}\n"
            "from symdrive_core.sim.config import SimConfig\n"
            "env = gym.make('{env_id}', package={package!r}, config=SimConfig(render=False))\n"
            "obs, _ = env.reset(seed=0)\n"
            "print(type(env.unwrapped).__name__, obs['state'].shape)\n")
    for module, env_id in (("symdrive_core.sim", "SymDrive-v0"), ("symdrive_core", "symdrive_core.sim:SymDrive-v0")):
        out = subprocess.run([sys.executable, "-c", code.format(module=module, env_id=env_id, package=str(DEMO))],
                             capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, out.stderr[-2000:]
        assert out.stdout.strip().endswith("SymDriveEnv (6,)"), out.stdout


@pytest.mark.parametrize("field, value", [
    ("dt", -0.1), ("dt", float("nan")), ("time_limit_s", 0.0), ("ego_wlh", (1.8, 0.0, 1.5)),
    ("ego_wlh", (1.8, 4.5)), ("max_steer", 1.6), ("max_speed", float("inf")), ("offroad_margin_m", -1.0),
    ("image_size", (0, 90)), ("image_size", (160.5, 90)), ("sumo_vehicles", -1), ("action", "throttle"),
    ("traffic", "carla"), ("camera_ahead_m", float("nan")),
])
def test_config_refuses_values_no_drive_runs_with(field, value):
    with pytest.raises(ValueError, match=f"^{field}: "):
        SimConfig(**{field: value})


def test_config_takes_numpy_numbers_and_the_defaults():
    cfg = SimConfig(dt=np.float64(0.05), image_size=(np.int64(160), np.int64(90)), sumo_vehicles=np.int64(3))
    assert cfg.dt == 0.05 and SimConfig().action == "accel_steer"
    assert SimConfig(route_end_margin_m=-1e6).route_end_margin_m == -1e6  # past the route: only time ends it
