"""Every knob of the simulator, with its default, in one dataclass (defaults live here only)."""

from __future__ import annotations

import math
import numbers
from dataclasses import asdict, dataclass, field

from ..diffusion.config import SAMPLERS, SamplerConfig

ACTIONS = ("accel_steer", "waypoint")
TRAFFIC = ("replay", "sumo")


@dataclass
class SimConfig:
    # Time: seconds per step; None = the package's frame interval (median of its timestamps' steps).
    dt: float | None = None
    # Episode time limit in seconds; None = time_limit_factor x the recorded drive's duration.
    time_limit_s: float | None = None
    time_limit_factor: float = 2.0
    # Ego vehicle: wlh = (width, length, height) metres; wheelbase of the bicycle model.
    ego_wlh: tuple[float, float, float] = (1.85, 4.6, 1.5)
    wheelbase_m: float = 2.8
    # Where the recorded camera sits on the ego: metres ahead of the box centre (the ego's
    # ground position at frame 0 is the camera's, moved back by this much along the heading).
    camera_ahead_m: float = 0.5
    # Camera height above the ground when the package has no road to read the ground from.
    camera_height_m: float = 1.6
    # Action limits: acceleration [m/s^2] and front-wheel steering angle [rad]; actions outside
    # (or not finite) end the episode with reason "invalid_action".
    max_accel: float = 4.0
    max_brake: float = 8.0
    max_steer: float = 0.6
    max_speed: float = 40.0  # m/s; the model clamps the speed to [0, max_speed]
    # Action space: "accel_steer" = [acceleration m/s^2, steering rad]; "waypoint" = [x, y, speed]:
    # a target point in the ego frame (metres from the box centre, x forward, y left) and a target
    # speed in [0, max_speed] m/s, turned into acceleration and steering (clipped to the limits
    # above) by pure pursuit and a proportional speed controller with this gain (1/s).
    action: str = "accel_steer"
    waypoint_speed_gain: float = 2.0
    # The farthest waypoint, metres from the ego box's centre along x and along y.
    waypoint_reach_m: float = 100.0
    # Actions scaled to [-1, 1] (a speed to [0, 1]) instead of physical units; see spaces.py.
    normalized_actions: bool = False
    # Road: without ground_truth.road, a corridor this wide each side of the recorded path.
    corridor_half_width_m: float = 3.5
    # Off-road when any footprint corner lies this far beyond the road's edge.
    offroad_margin_m: float = 0.0
    # The route (the recorded ego path) ends this far before its last point (negative: past it, so
    # only the time limit ends an episode, as a benchmark of steps wants).
    route_end_margin_m: float = 1.0
    # Footprint of actors without wlh.
    default_actor_wlh: tuple[float, float, float] = (1.8, 4.5, 1.5)
    # Observations: render the cameras (False: state only, for tests and planners without vision).
    render: bool = True
    cameras: list[str] | None = None  # None = every camera of the package
    image_size: tuple[int, int] | None = None  # (width, height); None = the package's own
    device: str = "cpu"
    # Online restoration of off-path views (see restore.py): when the ego is more than
    # restore_threshold_m sideways of the recorded path, each camera's background goes through the
    # restorer, auto-regressively (step restore_ar_step_m) from the nearest recorded frame, cached
    # per (frame, camera, offset rounded to restore_offset_round_m), sampled as the pipeline samples
    # (the built-in restorer's sampler: one evaluation from a noise-free start).
    restore: bool = False
    restore_threshold_m: float = 0.5
    restore_offset_round_m: float = 0.25
    restore_ar_step_m: float = 0.5
    restore_sampler: SamplerConfig = field(default_factory=lambda: SAMPLERS["builtin"])
    # Traffic: "replay" keeps the package's actors on their recorded poses; "sumo" drives
    # vehicles with SUMO/TraCI around the ego.
    traffic: str = "replay"
    sumo_vehicles: int = 0  # SUMO traffic: vehicles spread over the road at the start
    sumo_speed: float = 13.89  # SUMO lane speed limit, m/s
    sumo_timeout_s: float = 300.0
    # Score thresholds (NAVSIM / nuPlan values; see scores.py).
    ttc_horizon_s: float = 1.0
    # The look-ahead is checked this often (or every step, when steps are shorter): a coarse --dt
    # would otherwise step over a car ahead.
    ttc_step_s: float = 0.1
    extra: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        """Refuse values no drive can run with when the config is built, from Python as from the
        command line: a negative step or a zero-length car would otherwise surface as NaN scores
        or a stalled episode far from the field that caused it."""
        positive = ["time_limit_factor", "wheelbase_m", "camera_height_m", "max_accel", "max_brake", "max_steer",
                    "max_speed", "waypoint_speed_gain", "waypoint_reach_m", "corridor_half_width_m",
                    "restore_offset_round_m", "restore_ar_step_m", "sumo_speed", "sumo_timeout_s", "ttc_horizon_s",
                    "ttc_step_s"]
        at_least_zero = ["offroad_margin_m", "restore_threshold_m"]
        for name in ("dt", "time_limit_s"):
            if getattr(self, name) is not None:
                positive.append(name)
        for name in positive:
            _check_number(name, getattr(self, name), 0.0, inclusive=False)
        for name in at_least_zero:
            _check_number(name, getattr(self, name), 0.0, inclusive=True)
        for name in ("camera_ahead_m", "route_end_margin_m"):
            _check_number(name, getattr(self, name), -math.inf, inclusive=False)
        if not self.max_steer < math.pi / 2:
            raise ValueError(f"max_steer: expected below pi/2 rad (a wheel turned 90 degrees), got {self.max_steer}")
        for name in ("ego_wlh", "default_actor_wlh"):
            value = getattr(self, name)
            if len(value) != 3:
                raise ValueError(f"{name}: expected (width, length, height), got {value!r}")
            for v in value:
                _check_number(name, v, 0.0, inclusive=False)
        if self.image_size is not None and (
            len(self.image_size) != 2 or any(not isinstance(v, numbers.Integral) or v < 1 for v in self.image_size)
        ):
            raise ValueError(f"image_size: expected (width, height) in whole pixels, got {self.image_size!r}")
        if not isinstance(self.sumo_vehicles, numbers.Integral) or self.sumo_vehicles < 0:
            raise ValueError(f"sumo_vehicles: expected a count of at least 0, got {self.sumo_vehicles!r}")
        for name, allowed in (("action", ACTIONS), ("traffic", TRAFFIC)):
            if getattr(self, name) not in allowed:
                raise ValueError(f"{name}: expected one of {', '.join(allowed)}, got {getattr(self, name)!r}")

    def to_json(self) -> dict:
        return asdict(self)


def _check_number(name: str, value, low: float, *, inclusive: bool) -> None:
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value) and (
        value >= low if inclusive else value > low)
    if not ok:
        bound = "" if low == -math.inf else f" {'at least' if inclusive else 'above'} {low:g}"
        raise ValueError(f"{name}: expected a finite number{bound}, got {value!r}")
