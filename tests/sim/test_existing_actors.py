"""Recorded (existing) actors in the simulator: traffic exactly as inserted ones, on their edited poses."""

import copy

import numpy as np
import pytest

from symdrive_core.scene.poses import Pose
from symdrive_core.sim import SimConfig, SymDriveEnv
from symdrive_core.sim.agents import IDMAgent, ReplayAgent
from symdrive_core.sim.runner import run_episode

from .conftest import only_actors, park

STATE_ONLY = SimConfig(render=False)


def recorded(manifest, actor_id: str, *, reconstructed: bool = True):
    """``actor_id`` turned into a vehicle the drive recorded (before reconstruction: no assets)."""
    actor = manifest.actor(actor_id)
    actor.kind = "existing"
    if not reconstructed:
        actor.splats = actor.mesh = None
    return actor


def ahead_of_ego(manifest, distance: float):
    """(x, y, yaw) ``distance`` metres ahead of the ego's start, in its lane."""
    env = SymDriveEnv(manifest, STATE_ONLY)
    x0, y0, yaw0 = env.recorded_xy[0, 0], env.recorded_xy[0, 1], env.recorded_yaw[0]
    return x0 + distance * np.cos(yaw0), y0 + distance * np.sin(yaw0), yaw0


def test_replay_follows_the_edited_poses_not_the_recorded_ones(demo):
    actor = recorded(demo, "insert_1")
    actor.recorded_poses = actor.poses
    actor.poses = [None if p is None else Pose(p.translation + [0.0, 2.0, 0.0], p.rotation)
                   for p in actor.recorded_poses]
    env = SymDriveEnv(demo, STATE_ONLY)
    seen = 0
    for f, pose in zip(demo.frames, actor.poses):
        states = {s.id: s for s in env.traffic.states(f.timestamp, env.dt)}
        assert ("insert_1" in states) == (pose is not None)
        if pose is not None:
            np.testing.assert_allclose(states["insert_1"].pose.translation, pose.translation, atol=1e-9)
            seen += 1
    assert seen > 0


def test_a_removed_recorded_vehicle_is_not_traffic(demo):
    actor = recorded(demo, "insert_1")
    actor.recorded_poses, actor.poses = actor.poses, [None] * len(demo.frames)
    env = SymDriveEnv(demo, STATE_ONLY)
    assert all("insert_1" not in {s.id for s in env.traffic.states(f.timestamp, env.dt)} for f in demo.frames)
    run_episode(env, ReplayAgent, seed=0)
    assert not any(a["id"] == "insert_1" for h in env.history for a in h["actors"])


@pytest.mark.parametrize("agent", [ReplayAgent, IDMAgent])
@pytest.mark.parametrize("reconstructed", [True, False])
def test_recorded_and_inserted_vehicles_are_the_same_traffic(demo, agent, reconstructed):
    """A car parked in the ego's lane: the same episode whether the drive recorded it or it was inserted."""
    x, y, yaw = ahead_of_ego(demo, 25.0)
    park(only_actors(demo, {"insert_2"}), "insert_2", x, y, yaw)
    histories = []
    for kind in ("inserted", "existing"):
        m = copy.deepcopy(demo)
        if kind == "existing":
            recorded(m, "insert_2", reconstructed=reconstructed)
        env = SymDriveEnv(m, STATE_ONLY)
        rec = run_episode(env, agent, seed=0)
        histories.append(env.history)
    assert histories[0] == histories[1]
    if agent is IDMAgent:  # it followed the parked car and stopped behind it
        assert rec["end_reason"] == "time_limit" and histories[1][-1]["v"] < 0.5
        assert min(h["min_gap"] for h in histories[1]) > 0.0


def test_a_vehicle_not_reconstructed_yet_is_not_drawn(demo):
    """Rendered with an existing actor without assets in view: the picture of the empty street;
    once reconstructed (a splat PLY) it is drawn as an inserted one."""
    x, y, yaw = ahead_of_ego(demo, 10.0)
    park(only_actors(demo, {"insert_2"}), "insert_2", x, y, yaw)
    config = SimConfig(image_size=(32, 18), time_limit_s=0.1)

    def first_image(m):
        obs, _ = SymDriveEnv(m, config).reset(seed=0)
        return obs["images"]["front"]

    empty = first_image(only_actors(copy.deepcopy(demo), set()))
    pending = copy.deepcopy(demo)
    recorded(pending, "insert_2", reconstructed=False)
    np.testing.assert_array_equal(first_image(pending), empty)
    reconstructed = copy.deepcopy(demo)
    recorded(reconstructed, "insert_2")
    drawn = first_image(reconstructed)
    assert np.abs(drawn.astype(int) - empty).max() > 50
    np.testing.assert_array_equal(drawn, first_image(demo))


def test_sumo_vehicles_wear_recorded_vehicles_as_inserted_ones(demo):
    pytest.importorskip("traci")
    config = SimConfig(render=False, traffic="sumo", sumo_vehicles=6, time_limit_s=2.0)
    runs = []
    for kind in ("inserted", "existing"):
        m = copy.deepcopy(demo)
        for a in m.actors:
            a.kind = kind
        env = SymDriveEnv(m, config)
        try:
            run_episode(env, IDMAgent, seed=1)
            runs.append(([t[0] for t in env.traffic.templates], env.history))
        finally:
            env.close()
    assert runs[0] == runs[1]
    assert runs[1][0] == [a.id for a in demo.actors] and any(h["actors"] for h in runs[1][1])
