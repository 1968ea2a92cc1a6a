"""SUMO in the loop: traffic reacts to the ego pushed into SUMO each step."""

import numpy as np
import pytest

pytest.importorskip("traci")

from symdrive_core.sim import SimConfig, SymDriveEnv  # noqa: E402
from symdrive_core.sim.agents import IDMAgent  # noqa: E402
from symdrive_core.sim.runner import run_episode  # noqa: E402

from .conftest import DEMO  # noqa: E402


def test_follower_reacts_to_a_braking_ego():
    env = SymDriveEnv(DEMO, SimConfig(render=False, traffic="sumo", sumo_vehicles=0, time_limit_s=6.0))
    try:
        env.reset(seed=0)
        conn = env.traffic.conn
        edge, pos, lane = conn.simulation.convertRoad(*env.traffic._front(env.ego.x, env.ego.y, env.ego.yaw))
        conn.vehicle.add("f", routeID="forward", typeID="t0", departLane=str(lane), departPos=f"{pos - 25:.2f}",
                         departSpeed="12")
        conn.vehicle.setLaneChangeMode("f", 0)  # it may only brake
        env.traffic.types["f"] = env.traffic.templates[0]
        speeds, gaps = [], []
        while env.end_reason is None:
            env.step([-env.config.max_brake, 0.0])  # the ego stops in its lane and stays
            f = [a for a in env.actors if a.id == "f"]
            if f:
                speeds.append(float(np.linalg.norm(f[0].velocity)))
                gaps.append(env.history[-1]["min_gap"])
        assert env.end_reason == "time_limit"
        assert speeds and speeds[-1] < 0.5 and max(speeds) >= 10.0  # it came on fast and stopped
        assert min(gaps) > 0.0  # behind the ego, never into it
    finally:
        env.close()


def test_sumo_episode_is_deterministic():
    env = SymDriveEnv(DEMO, SimConfig(render=False, traffic="sumo", sumo_vehicles=8))
    try:
        a = run_episode(env, IDMAgent, 2)
        ha = [dict(h) for h in env.history]
        b = run_episode(env, IDMAgent, 2)
        assert a["scores"] == b["scores"] and ha == env.history
        assert any(h["actors"] for h in ha)
    finally:
        env.close()
