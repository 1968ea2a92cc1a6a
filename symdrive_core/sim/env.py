"""``SymDriveEnv``: a scene package as a Gymnasium environment.

Observation (a dict):

* ``images``: ``{camera name: uint8 [H, W, 3]}``, the package's cameras rigidly attached to the
  ego at its current pose, rendered by the splat renderer (background plus every actor at its
  pose for the current time). Left out when ``config.render`` is False.
* ``state``: float32 ``[speed m/s, heading rad (world), heading relative to the route rad,
  offset from the lane's middle m (positive = left), lane index from the right, progress along
  the route m]``, each inside the bounds the observation space declares (:mod:`.spaces`). The
  lane offset is clipped to the road's half-width plus half a lane: the ego's centre would have
  to be a half road-width beyond the edge, which ends the episode first.

Action (``config.action``):

* ``"accel_steer"`` (default): ``[acceleration m/s^2, front-wheel steering rad]`` through the
  kinematic bicycle model (:mod:`.bicycle`) with the limits of :class:`.config.SimConfig`;
* ``"waypoint"``: ``[x, y, speed]``, a target point in the ego frame (metres from the ego box's
  centre, x forward, y left) and a target speed (m/s, in [0, max_speed]); the built-in low-level
  controller (:func:`.bicycle.waypoint_control`: pure pursuit for the steering, the same function
  the built-in agents steer with, and proportional speed control) turns it into acceleration and
  steering, clipped to the same limits, for the same bicycle model.

With ``config.normalized_actions`` both take entries in [-1, 1] instead (:mod:`.spaces`). An
action is valid exactly when ``action_space`` contains it (compared in the space's float32);
anything else (NaN, out of range, the wrong length) ends the episode with reason
``invalid_action``.

The ego: at frame 0 the reference camera (the package's ``ground_truth.camera`` or its first)
gives the ego pose: its ground point moved back ``camera_ahead_m`` along the recorded heading,
standing on the road. Each camera keeps its frame-0 offset to that pose for the whole episode.

Reward: metres of progress along the route in the step (scores are computed separately by
:mod:`.scores`). The same seed gives the same episode. Registered with Gymnasium as
``SymDrive-v0`` (by :mod:`symdrive_core.sim`): ``gymnasium.make("symdrive_core.sim:SymDrive-v0",
package=..., config=SimConfig(...))``.
"""

from __future__ import annotations

import time
from pathlib import Path

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .. import conventions
from ..scene import Manifest, ManifestError, load_manifest
from ..scene.ground_truth import truth_camera
from . import episode as ep
from . import spaces as sim_spaces
from .bicycle import EgoState, step, waypoint_control
from .config import SimConfig
from .road import Route, drivable_area
from .traffic import ReplayTraffic


def _yaw_matrix(x: float, y: float, z: float, yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    M = np.eye(4)
    M[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    M[:3, 3] = [x, y, z]
    return M


class SymDriveEnv(gym.Env):
    metadata = {"render_modes": ["rgb_array"]}

    def __init__(self, package: str | Path | Manifest, config: SimConfig | None = None, *,
                 allow_external_assets: bool = False, render_mode: str | None = None):
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode: expected one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        self.config = cfg = config or SimConfig()
        self.manifest = m = package if isinstance(package, Manifest) else load_manifest(
            package, allow_external=allow_external_assets)
        if cfg.restore and cfg.render and not m.background_splats:  # found now, not when the ego first leaves the path
            raise ManifestError(m.path or m.root, "sim's restore needs the package's background splats (views off "
                                "the recorded path are rendered from them): 'symdrive reconstruct' fits them",
                                "background.splats")
        times = np.array([f.timestamp for f in m.frames], dtype=np.float64)
        self.times = times
        self.dt = float(cfg.dt if cfg.dt is not None else (np.median(np.diff(times)) if len(times) > 1 else 0.1))
        if not self.dt > 0:
            raise ValueError(f"dt must be positive, got {self.dt}")
        self.metadata = {**self.metadata, "render_fps": 1.0 / self.dt}
        duration = float(times[-1] - times[0])
        self.time_limit = float(cfg.time_limit_s if cfg.time_limit_s is not None
                                else max(cfg.time_limit_factor * duration, 10 * self.dt))
        names = cfg.cameras or [c.name for c in m.cameras]
        self.cameras = [m.camera(n) for n in names]
        ref = truth_camera(m)
        self.wlh = np.asarray(cfg.ego_wlh, dtype=np.float64)

        # The recorded ego path, from the reference camera.
        cam_xyz = np.array([cf.camera_to_world[:3, 3] for cf in ref.frames])
        fwd = np.array([cf.camera_to_world[:3, 2] for cf in ref.frames])
        yaw_cam = np.arctan2(fwd[:, 1], fwd[:, 0])
        if len(times) > 1:
            vel = np.gradient(cam_xyz[:, :2], times, axis=0)
            moving = np.linalg.norm(vel, axis=1) > 0.1
            yaw = np.where(moving, np.arctan2(vel[:, 1], vel[:, 0]), yaw_cam)
        else:
            vel, yaw = np.zeros((1, 2)), yaw_cam
        heading = np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
        path_xy = cam_xyz[:, :2] - cfg.camera_ahead_m * heading
        self.area = drivable_area(m.ground_truth, m.path or m.root, path_xy, cam_xyz[:, 2] - cfg.camera_height_m,
                                  cfg.corridor_half_width_m)
        self.route = Route.from_path(path_xy)
        self.recorded_xy, self.recorded_yaw = path_xy, yaw
        self.recorded_speed = np.linalg.norm(vel, axis=1)
        z0 = float(self.area.ground(path_xy[:1])[0]) + 0.5 * self.wlh[2]
        E0 = _yaw_matrix(path_xy[0, 0], path_xy[0, 1], z0, yaw[0])
        E0_inv = conventions.invert_rigid(E0)
        self.camera_offsets = {c.name: E0_inv @ c.frames[0].camera_to_world for c in self.cameras}

        self.traffic = self._make_traffic()
        self._renderer = None
        self.restorer = None
        if cfg.restore and cfg.render:
            from .restore import OnlineRestorer

            self.restorer = OnlineRestorer(self)
        self.action_space = sim_spaces.action_space(cfg)
        self.lane_offset_bound = self.area.half_width + 0.5 * self.area.lane_width
        obs = {"state": sim_spaces.state_space(self.route.length, self.area.lanes, self.lane_offset_bound, cfg)}
        if cfg.render:
            obs["images"] = spaces.Dict({c.name: spaces.Box(0, 255, (*self.image_size(c)[::-1], 3), np.uint8)
                                         for c in self.cameras})
        self.observation_space = spaces.Dict(obs)
        self.timing = {"render": 0.0, "restore": 0.0, "traffic": 0.0, "physics": 0.0}
        self.ego: EgoState | None = None

    # ------------------------------------------------------------------ set-up helpers

    def _make_traffic(self):
        if self.config.traffic == "replay":
            return ReplayTraffic(self.manifest, self.config.default_actor_wlh)
        if self.config.traffic == "sumo":
            from .sumo import SumoTraffic

            return SumoTraffic(self, self.config)
        raise ValueError(f"traffic: expected 'replay' or 'sumo', got {self.config.traffic!r}")

    @property
    def action_limits(self) -> tuple[tuple[float, float], tuple[float, float]]:
        c = self.config
        return (-c.max_brake, c.max_accel), (-c.max_steer, c.max_steer)

    def image_size(self, cam) -> tuple[int, int]:
        return tuple(self.config.image_size) if self.config.image_size else (cam.width, cam.height)

    @property
    def renderer(self):
        if self._renderer is None:
            from ..pipeline.scene_render import SceneRenderer

            self._renderer = SceneRenderer(self.manifest, device=self.config.device)
        return self._renderer

    # ------------------------------------------------------------------ poses

    def ego_matrix(self, state: EgoState | None = None) -> np.ndarray:
        s = state or self.ego
        z = float(self.area.ground(np.array([[s.x, s.y]]))[0]) + 0.5 * self.wlh[2]
        return _yaw_matrix(s.x, s.y, z, s.yaw)

    def camera_to_world(self, camera: str, state: EgoState | None = None) -> np.ndarray:
        return self.ego_matrix(state) @ self.camera_offsets[camera]

    def lateral_offset_from_route(self, state: EgoState | None = None) -> float:
        s = state or self.ego
        from ..scene.road import project_onto

        lat, _, _ = project_onto(self.route.xy, np.array([[s.x, s.y]]))
        return float(lat[0])

    # ------------------------------------------------------------------ gym API

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.seed_value = seed
        self.t = float(self.times[0])
        self.steps = 0
        v0 = min(float(self.recorded_speed[0]), self.config.max_speed)
        self.ego = EgoState(float(self.recorded_xy[0, 0]), float(self.recorded_xy[0, 1]),
                            float(self.recorded_yaw[0]), v0)
        self.timing = {"render": 0.0, "restore": 0.0, "traffic": 0.0, "physics": 0.0}
        t0 = time.perf_counter()
        self.traffic.reset(seed)
        self.actors = self.traffic.states(self.t, self.dt)
        self.timing["traffic"] += time.perf_counter() - t0
        self.history: list[dict] = []
        self.end_reason: str | None = None
        self.end_detail: str | None = None
        self._record(None)
        return self._observation(), self._info()

    def step(self, action):
        if self.ego is None:
            raise RuntimeError("call reset() before step()")
        if self.end_reason is not None:
            raise RuntimeError(f"the episode has ended ({self.end_reason}); call reset()")
        cfg = self.config
        problem = sim_spaces.check_action(action, self.action_space, sim_spaces.NAMES[cfg.action])
        if problem is not None:
            return self.end(ep.INVALID_ACTION, problem)
        u = sim_spaces.to_physical(np.asarray(action, dtype=np.float64).reshape(-1), cfg)
        if cfg.action == "waypoint":
            a, delta = waypoint_control(self.ego, u[:2], float(u[2]), cfg.wheelbase_m, cfg.waypoint_speed_gain,
                                        self.action_limits)
        else:
            a, delta = float(u[0]), float(u[1])
        t0 = time.perf_counter()
        before = self.route.progress(self.ego.xy)
        self.ego = step(self.ego, a, delta, self.dt, self.config.wheelbase_m, self.config.max_speed)
        self.t += self.dt
        self.steps += 1
        self.timing["physics"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        self.traffic.step(self.t, self.ego)
        self.actors = self.traffic.states(self.t, self.dt)
        self.timing["traffic"] += time.perf_counter() - t0
        hit = self._record(a)
        rect = ep.ego_footprint(self.ego.x, self.ego.y, self.ego.yaw, self.wlh)
        progress = self.history[-1]["progress"]
        reason, detail = None, None
        if hit:
            reason, detail = ep.COLLISION, "with " + ", ".join(hit)
        elif self.area.outside(rect, self.config.offroad_margin_m):
            reason, detail = ep.OFF_ROAD, f"lateral {self.history[-1]['road_lateral']:+.2f} m"
        elif progress >= self.route.length - self.config.route_end_margin_m:
            reason, detail = ep.ROUTE_END, f"{progress:.2f} m of {self.route.length:.2f} m"
        elif self.t - self.times[0] >= self.time_limit - 1e-9:
            reason, detail = ep.TIME_LIMIT, f"{self.time_limit:g} s"
        self.end_reason, self.end_detail = reason, detail
        obs = self._observation()
        return obs, progress - before, reason in ep.TERMINAL, reason == ep.TIME_LIMIT, self._info()

    def end(self, reason: str, detail: str = ""):
        """End the episode now with ``reason`` (an invalid action, an agent that raised)."""
        self.end_reason, self.end_detail = reason, detail
        if self.history:
            self.history[-1]["end"] = reason
        return self._observation(render=False), 0.0, True, False, self._info()

    def render(self):
        """The first camera's view (``render_mode="rgb_array"``); None without a render mode, as
        Gymnasium specifies."""
        if self.render_mode is None:
            return None
        return self.render_camera(self.cameras[0].name)

    def close(self):
        self.traffic.close()

    # ------------------------------------------------------------------ internals

    def _record(self, accel) -> list[str]:
        e = self.ego
        rect = ep.ego_footprint(e.x, e.y, e.yaw, self.wlh)
        centres = np.array([s.xy for s in self.actors]).reshape(-1, 2)
        yaws = np.array([s.yaw for s in self.actors])
        wlhs = np.array([s.wlh for s in self.actors]).reshape(-1, 3)
        hit, gaps = ep.collisions(rect, centres, yaws, wlhs)
        k, lane_off = self.area.lane_position(e.xy)
        self.history.append({
            "step": self.steps, "t": round(self.t - float(self.times[0]), 9), "x": e.x, "y": e.y, "yaw": e.yaw,
            "v": e.v, "accel": e.accel, "steer": e.steer, "progress": self.route.progress(e.xy),
            "lane": k, "lane_offset": lane_off, "road_lateral": float(self.area.lateral(e.xy[None])[0]),
            "min_gap": float(gaps.min()) if len(gaps) else None,
            "ttc": self._ttc(centres, yaws, wlhs),
            "actors": [{"id": s.id, "x": float(s.xy[0]), "y": float(s.xy[1]), "yaw": s.yaw,
                        "wlh": [float(v) for v in s.wlh]} for s in self.actors],
        })
        return [self.actors[i].id for i in hit]

    def _ttc(self, centres, yaws, wlhs) -> float | None:
        """Time until the ego, driving on at constant speed and heading, overlaps an actor moving
        on at its current velocity, within ``ttc_horizon_s`` (None: no overlap ahead, or the ego
        stands still, as NAVSIM ignores a stationary ego)."""
        e = self.ego
        if e.v < 0.05 or len(centres) == 0:
            return None
        vel = np.array([s.velocity for s in self.actors])
        step = min(self.dt, self.config.ttc_step_s)
        for k in range(int(np.floor(self.config.ttc_horizon_s / step + 1e-9)) + 1):
            tau = k * step
            rect = ep.ego_footprint(e.x + e.v * tau * np.cos(e.yaw), e.y + e.v * tau * np.sin(e.yaw), e.yaw,
                                    self.wlh)
            hit, _ = ep.collisions(rect, centres + vel * tau, yaws, wlhs)
            if len(hit):
                return tau
        return None

    def _state(self) -> np.ndarray:
        e, h = self.ego, self.history[-1]
        rel = e.yaw - self.route.heading_at(h["progress"])
        rel = float(np.arctan2(np.sin(rel), np.cos(rel)))
        lane_offset = float(np.clip(h["lane_offset"], -self.lane_offset_bound, self.lane_offset_bound))
        return np.array([e.v, e.yaw, rel, lane_offset, h["lane"], h["progress"]], dtype=np.float32)

    def _observation(self, render: bool = True) -> dict:
        obs = {"state": self._state()}
        if self.config.render:
            if render:
                obs["images"] = {c.name: self.render_camera(c.name) for c in self.cameras}
            else:
                obs["images"] = {c.name: np.zeros((*self.image_size(c)[::-1], 3), np.uint8) for c in self.cameras}
        return obs

    def _info(self) -> dict:
        return {"t": self.t - float(self.times[0]), "step": self.steps, "end_reason": self.end_reason,
                "end_detail": self.end_detail, "progress": self.history[-1]["progress"],
                "route_length": self.route.length}

    def off_path(self) -> bool:
        """Whether the ego is further sideways of the recorded path than ``restore_threshold_m``."""
        return abs(self.lateral_offset_from_route()) > self.config.restore_threshold_m

    def render_camera(self, camera: str, restore: bool | None = None) -> np.ndarray:
        """uint8 [H, W, 3] view of ``camera`` at the ego's current pose, traffic at its poses.
        With ``config.restore`` (or ``restore=True``) and the ego off the recorded path, the
        background is the restorer's (:mod:`.restore`) with the traffic rendered over it."""
        import torch

        from ..splat.render import Layer, render_layers

        t0 = time.perf_counter()
        r = self.renderer
        cam = self.manifest.camera(camera)
        w, h = self.image_size(cam)
        K = conventions.scale_intrinsics(cam.frames[0].K, w / cam.width, h / cam.height)
        c2w = self.camera_to_world(camera)
        restored = None
        if (self.restorer is not None if restore is None else restore) and self.off_path():
            if self.restorer is None:
                from .restore import OnlineRestorer

                self.restorer = OnlineRestorer(self)
            t1 = time.perf_counter()
            restored = self.restorer.background(camera, c2w)
            self.timing["restore"] += time.perf_counter() - t1
            t0 += time.perf_counter() - t1
        layers = [] if r.background is None or restored is not None else [Layer(r.background, None, None, 0)]
        by_id = {a.id: a for a in self.manifest.actors}
        for s in self.actors:
            asset = s.asset or s.id
            if asset in r.actors:
                layers.append(Layer(r.actors[asset], torch.as_tensor(s.pose.R, dtype=torch.float32),
                                    torch.as_tensor(s.pose.translation, dtype=torch.float64),
                                    by_id[asset].instance_id if asset in by_id else 0))
        black = torch.zeros(3, dtype=torch.float32, device=r.device)
        if restored is not None and not layers:
            rgb = restored
        else:
            with torch.no_grad():
                out = render_layers(layers, torch.as_tensor(conventions.invert_rigid(c2w), dtype=torch.float64),
                                    torch.as_tensor(K, dtype=torch.float32), w, h,
                                    background=black if restored is not None else r.background_color)
            rgb = out["rgb"].detach().cpu().numpy()
            if restored is not None:  # traffic (premultiplied over black) over the restored background
                rgb = rgb + (1.0 - out["alpha"].detach().cpu().numpy()) * restored
        self.timing["render"] += time.perf_counter() - t0
        return (np.clip(rgb, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
