"""Driving agents: what ``symdrive sim --agent`` runs.

An agent has ``reset(env, seed)`` (called at the start of every episode with the environment,
whose route, road and traffic built-in agents read) and ``act(observation) -> [acceleration,
steering]``. ``MODULE:CLASS`` names any class with that interface (constructed without
arguments). Built-in:

* ``replay``: follows the recorded path at the recorded speed (pure pursuit + speed tracking);
* ``idm``: the Intelligent Driver Model (Treiber, Hennecke and Helbing 2000) behind the nearest
  vehicle ahead in its lane, and pure pursuit (Coulter 1992) along the lane's middle; its desired
  speed drops before bends so that the lateral acceleration stays within ``a_lat``;
* ``cut-in``: an aggressive scripted lane change into the neighbouring lane one second in,
  over ``duration`` seconds, then lane keeping at constant speed.
"""

from __future__ import annotations

import importlib

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from .bicycle import pure_pursuit_steer, world_to_ego
from .spaces import from_physical

__all__ = ["Agent", "BUILTIN", "load_agent", "pure_pursuit_steer"]


class Agent:
    """Base class: holds the environment and clips its commands to the limits."""

    def reset(self, env, seed: int | None = None) -> None:
        self.env = env
        self.rng = np.random.default_rng(seed)

    def act(self, obs) -> np.ndarray:
        raise NotImplementedError

    def command(self, accel: float, steer: float) -> np.ndarray:
        """The action in the environment's action space: ``[accel, steer]``, or, with
        ``action="waypoint"``, ``[x, y, speed]``: the last pure-pursuit target (in the ego frame)
        and the speed ``accel`` reaches in one step; clipped to the limits and scaled as the
        space asks (:mod:`.spaces`)."""
        env = self.env
        (alo, ahi), _ = env.action_limits
        if env.config.action == "waypoint":
            x, y = world_to_ego(env.ego, self.target)
            physical = [x, y, env.ego.v + float(np.clip(accel, alo, ahi)) * env.dt]
        else:
            physical = [accel, steer]
        return from_physical(physical, env.config)

    def follow(self, s_ahead: float, lateral: float, v_target: float, gain: float = 1.0) -> tuple[float, float]:
        """Pure pursuit to the point ``s_ahead`` metres ahead of the ego's progress, ``lateral``
        metres left of the route, and a proportional speed controller."""
        e, env = self.env.ego, self.env
        s = env.route.progress(e.xy)
        self.target = env.route.point_at(s + s_ahead, lateral)
        steer = pure_pursuit_steer(e.x, e.y, e.yaw, self.target, env.config.wheelbase_m)
        return gain * (v_target - e.v), steer

    def lookahead(self) -> float:
        return max(4.0, 0.8 * self.env.ego.v)


class ReplayAgent(Agent):
    """Drives the recorded path at the recorded speed."""

    def act(self, obs):
        env = self.env
        t = env.t + env.dt
        v_target = float(np.interp(t, env.times, env.recorded_speed))
        # The recorded path is the route itself; reach the recorded speed in one step.
        accel, steer = self.follow(self.lookahead(), 0.0, v_target, gain=1.0 / env.dt)
        return self.command(accel, steer)


class IDMAgent(Agent):
    """IDM car following + pure-pursuit lane keeping in the lane it starts in, slowing for bends."""

    a_max = 1.5  # m/s^2
    b_comf = 2.0  # m/s^2
    time_headway = 1.5  # s
    min_gap = 2.0  # m
    delta = 4.0
    a_lat = 2.0  # m/s^2, lateral acceleration allowed in bends
    chord = 5.0  # m, the span over which the route's curvature is measured

    def reset(self, env, seed=None):
        super().reset(env, seed)
        self.v0 = max(float(np.max(env.recorded_speed)), 1.0)
        # Keep the route's own lateral place (the lane the recording drove in).
        self.lateral = 0.0

    def leader(self) -> tuple[float, float] | None:
        """(gap m, speed m/s along the route) of the nearest actor ahead in the ego's lane."""
        env, e = self.env, self.env.ego
        s_ego = env.route.progress(e.xy)
        best = None
        half_lane = 0.5 * env.area.lane_width
        from ..scene.road import project_onto

        for a in env.actors:
            lat, _, _ = project_onto(env.route.xy, a.xy[None])
            if abs(lat[0] - self.lateral) > half_lane + 0.5 * a.wlh[0]:
                continue
            s = env.route.progress(a.xy)
            gap = s - s_ego - 0.5 * env.wlh[1] - 0.5 * a.wlh[1]
            if s <= s_ego:
                continue
            h = env.route.heading_at(s)
            v = float(a.velocity @ np.array([np.cos(h), np.sin(h)]))
            if best is None or gap < best[0]:
                best = (gap, v)
        return best

    def desired_speed(self) -> float:
        """``v0``, or less where a bend ahead asks for less: a point ``d`` metres ahead with
        curvature k allows ``sqrt(a_lat / k + 2 b d)``, planned with ``b = b_comf / 4`` (the
        free-road term then brakes only 10 % above it, at ``b``). Each point takes the sharpest
        curvature within the next chord: measured over a chord, a bend's start shows half of it."""
        env, v = self.env, self.env.ego.v
        s = env.route.progress(env.ego.xy)
        b = 0.25 * self.b_comf
        reach = max(v, self.v0) ** 2 / (2.0 * b) + self.lookahead()
        span = int(np.ceil(self.chord))
        d = np.arange(0.0, reach + 1.0, 1.0)
        k = env.route.curvature(s + np.arange(0.0, reach + 1.0 + span, 1.0), self.chord)
        k = sliding_window_view(k, span + 1).max(axis=1)[: len(d)]
        bends = k > 0
        if not bends.any():
            return self.v0
        return float(max(0.1, min(self.v0, np.min(np.sqrt(self.a_lat / k[bends] + 2.0 * b * d[bends])))))

    def free_road(self, v: float, v0: float) -> float:
        """IDM's free-road acceleration; above ``v0`` the improved IDM's (Treiber and Kesting
        2013), which brakes at most ``b_comf`` where plain IDM would brake ever harder."""
        if v > v0:
            return -self.b_comf * (1.0 - (v0 / v) ** (self.a_max * self.delta / self.b_comf))
        return self.a_max * (1.0 - (v / v0) ** self.delta)

    def idm(self) -> float:
        v = self.env.ego.v
        free = self.free_road(v, self.desired_speed())
        lead = self.leader()
        if lead is None:
            return free
        gap, v_lead = lead
        s_star = self.min_gap + max(0.0, v * self.time_headway + v * (v - v_lead) / (2 * np.sqrt(self.a_max * self.b_comf)))
        return free - self.a_max * (s_star / max(gap, 0.1)) ** 2

    def act(self, obs):
        _, steer = self.follow(self.lookahead(), self.lateral, self.env.ego.v)
        return self.command(self.idm(), steer)


class CutInAgent(IDMAgent):
    """A scripted aggressive lane change into the neighbouring lane (left when there is room,
    else right), starting ``start`` seconds in (jittered by the seed) and taking ``duration``
    seconds, at constant speed and without looking."""

    start = 1.0
    duration = 1.0

    def reset(self, env, seed=None):
        super().reset(env, seed)
        k, _ = env.area.lane_position(env.ego.xy)
        side = 1 if k + 1 < env.area.lanes else -1
        self.shift = side * env.area.lane_width
        self.t_start = self.start + float(self.rng.uniform(-0.2, 0.2))

    def act(self, obs):
        env = self.env
        t = env.t - float(env.times[0])
        u = float(np.clip((t - self.t_start) / self.duration, 0.0, 1.0))
        lateral = self.shift * (3 * u * u - 2 * u * u * u)  # smoothstep
        _, steer = self.follow(max(3.0, 0.5 * env.ego.v), lateral, env.ego.v)
        return self.command(0.0, steer)


BUILTIN = {"replay": ReplayAgent, "idm": IDMAgent, "cut-in": CutInAgent}


def load_agent(spec: str):
    """A built-in agent's name or ``MODULE:CLASS`` -> a class (agents are made per episode)."""
    if spec in BUILTIN:
        return BUILTIN[spec]
    if ":" not in spec:
        raise ValueError(f"--agent: expected one of {', '.join(BUILTIN)} or MODULE:CLASS, got {spec!r}")
    module, _, name = spec.partition(":")
    obj = importlib.import_module(module)
    for part in name.split("."):
        obj = getattr(obj, part)
    return obj
