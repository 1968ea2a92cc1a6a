"""Random agents against the environment: actions drawn from ``action_space.sample()`` or set
exactly on the space's bounds, many short episodes, both action types, at a tiny image size.
Nothing raises, every observation is finite and inside the observation space, every episode ends
with a reason, and no action the space contains is refused."""

import numpy as np
import pytest

from symdrive_core.sim import SimConfig, SymDriveEnv
from symdrive_core.sim.episode import REASONS

KINDS = [("accel_steer", False), ("accel_steer", True), ("waypoint", False), ("waypoint", True)]


def _random_or_bound(space, rng):
    """A sample, or (one time in two) each entry at its low or its high bound."""
    if rng.random() < 0.5:
        return space.sample()
    return np.where(rng.random(space.shape) < 0.5, space.low, space.high)


def _drive_randomly(env, episodes: int) -> dict[str, int]:
    """``episodes`` episodes of random actions; the end reasons counted."""
    rng = np.random.default_rng(7)
    reasons: dict[str, int] = {}
    for episode in range(episodes):
        obs, _ = env.reset(seed=episode)
        env.action_space.seed(episode)
        assert env.observation_space.contains(obs)
        terminated = truncated = False
        while not (terminated or truncated):
            a = _random_or_bound(env.action_space, rng)
            assert env.action_space.contains(a)
            obs, reward, terminated, truncated, info = env.step(a)
            assert np.all(np.isfinite(obs["state"])) and np.isfinite(reward)
            assert env.observation_space.contains(obs), obs["state"]
        assert info["end_reason"] in REASONS and info["end_reason"] != "invalid_action", info
        assert terminated != truncated and truncated == (info["end_reason"] == "time_limit")
        reasons[info["end_reason"]] = reasons.get(info["end_reason"], 0) + 1
    return reasons


@pytest.mark.parametrize("action,normalized", KINDS)
def test_random_agents_on_the_demo_street(demo, action, normalized):
    """The street's road and lanes, its parked actors; state observations, many episodes."""
    env = SymDriveEnv(demo, SimConfig(render=False, action=action, normalized_actions=normalized))
    reasons = _drive_randomly(env, 60)
    assert sum(reasons.values()) == 60
    assert reasons.get("off_road", 0) > 0  # random steering leaves the road, and that ends the episode


@pytest.mark.parametrize("action,normalized", KINDS)
def test_random_agents_with_images(make_package, action, normalized):
    """A tiny package without road truth (the corridor), a car ahead, rendered at 16x9."""
    env = SymDriveEnv(make_package(), SimConfig(action=action, normalized_actions=normalized, image_size=(16, 9)))
    assert env.area.road is None
    reasons = _drive_randomly(env, 12)
    assert sum(reasons.values()) == 12
    obs = env.reset(seed=0)[0]
    assert obs["images"]["front"].shape == (9, 16, 3) and obs["images"]["front"].std() > 0
