"""The waypoint action: a target point in the ego frame and a target speed, followed by the
built-in pure-pursuit + speed controller."""

import numpy as np
import pytest

from symdrive_core.sim import SimConfig, SymDriveEnv
from symdrive_core.sim.agents import IDMAgent, ReplayAgent
from symdrive_core.sim.bicycle import EgoState, ego_to_world, waypoint_control, world_to_ego
from symdrive_core.sim.runner import run_episode

WAYPOINT = SimConfig(render=False, action="waypoint")


class RouteWaypoints:
    """Gives the route's next point (8 m ahead of the ego's progress) at the recorded speed."""

    def reset(self, env, seed=None):
        self.env = env

    def act(self, obs):
        env = self.env
        s = env.route.progress(env.ego.xy)
        x, y = world_to_ego(env.ego, env.route.point_at(s + 8.0))
        return np.array([x, y, float(np.max(env.recorded_speed))])


class NaNWaypoint(RouteWaypoints):
    def act(self, obs):
        if self.env.steps == 3:
            return np.array([np.nan, 0.0, 5.0])
        return super().act(obs)


def test_frames_round_trip():
    e = EgoState(3.0, -2.0, 0.7, 5.0)
    p = np.array([4.0, 1.5])
    assert np.allclose(world_to_ego(e, ego_to_world(e, p)), p)
    assert np.allclose(ego_to_world(e, (1.0, 0.0)), [3.0 + np.cos(0.7), -2.0 + np.sin(0.7)])


def test_controller_respects_limits():
    e = EgoState(0.0, 0.0, 0.0, 0.0)
    limits = ((-8.0, 4.0), (-0.6, 0.6))
    a, d = waypoint_control(e, (0.0, 3.0), 30.0, 2.8, 2.0, limits)  # far left, fast
    assert a == 4.0 and d == 0.6
    a, d = waypoint_control(EgoState(0, 0, 0, 20.0), (0.0, -3.0), 0.0, 2.8, 2.0, limits)
    assert a == -8.0 and d == -0.6
    a, d = waypoint_control(EgoState(0, 0, 0, 5.0), (10.0, 0.0), 5.0, 2.8, 2.0, limits)
    assert a == 0.0 and d == pytest.approx(0.0)


def test_route_waypoints_reach_the_end_on_the_road(demo):
    env = SymDriveEnv(demo, WAYPOINT)
    assert env.action_space.shape == (3,)
    rec = run_episode(env, RouteWaypoints, seed=0)
    assert rec["end_reason"] == "route_end"
    assert rec["scores"]["drivable_area_compliance"] == 1.0 and rec["scores"]["no_collision"] == 1.0
    assert rec["scores"]["route_completion"] > 0.95
    lat = [abs(env.lateral_offset_from_route(EgoState(h["x"], h["y"], h["yaw"], h["v"]))) for h in env.history]
    assert max(lat) < 0.5


@pytest.mark.parametrize("agent", [ReplayAgent, IDMAgent])
def test_builtin_agents_drive_in_waypoint_mode(demo, agent):
    rec = run_episode(SymDriveEnv(demo, WAYPOINT), agent, seed=0)
    assert rec["end_reason"] in ("route_end", "time_limit") and rec["scores"]["drivable_area_compliance"] == 1.0


def test_nan_waypoint_is_an_invalid_action(demo):
    env = SymDriveEnv(demo, WAYPOINT)
    rec = run_episode(env, NaNWaypoint, seed=0)
    assert rec["end_reason"] == "invalid_action" and "not finite" in rec["end_detail"]
    assert rec["steps"] == 3


@pytest.mark.parametrize("action", [[1.0, 0.0], [5.0, 0.0, -1.0], [5.0, 0.0, 1e3]])
def test_bad_waypoints(demo, action):
    env = SymDriveEnv(demo, WAYPOINT)
    env.reset(seed=0)
    *_, term, _, info = env.step(action)
    assert term and info["end_reason"] == "invalid_action"


def test_unknown_action_space(demo):
    with pytest.raises(ValueError, match="action"):
        SymDriveEnv(demo, SimConfig(render=False, action="throttle"))


def test_command_waypoint_action(tmp_path):
    import json

    from symdrive_core.cli import main

    from .conftest import DEMO

    assert main(["sim", str(DEMO), "--agent", "replay", "--action", "waypoint", "--no-render", "--no-video",
                 "--out", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["episodes"][0]["end_reason"] == "route_end"
    assert json.dumps(report).count('"waypoint"') >= 1


def test_command_normalized_actions(tmp_path):
    import json

    from symdrive_core.cli import main

    from .conftest import DEMO

    assert main(["sim", str(DEMO), "--agent", "replay", "--action", "waypoint", "--normalized-actions", "--no-render",
                 "--no-video", "--quiet", "--out", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["config"]["normalized_actions"] is True and report["config"]["render"] is False
    # Flags not given keep SimConfig's values.
    defaults = SimConfig().to_json()
    assert all(report["config"][k] == defaults[k] for k in ("traffic", "sumo_vehicles", "restore", "dt"))
    assert report["episodes"][0]["end_reason"] == "route_end"
