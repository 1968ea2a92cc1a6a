"""Tracks whose boxes are not one vehicle's motion, reported by actor and frame.

A tracker errs in ways a reconstruction must not fit as motion: a box that jumps metres in one
frame (a detection in error), an id handed to another vehicle (the box jumps, turns or changes
size from one frame to the next), a vehicle that leaves the images and comes back (trackers often
give the returning id to whichever vehicle appears). Fitted silently, a jump is smoothed into a
motion and one vehicle's Gaussians learn two cars. So ``import tracks`` checks each track's
consecutive boxes and names every frame where:

* ``jump``: the box lies farther than ``jump_m`` (plus what ``max_accel_mps2`` allows over the
  interval) from where the track's last plausible step puts it, or moves faster than
  ``max_speed_mps`` from the box before (the only test right after a track starts or is cut:
  it has no motion to extrapolate);
* ``turn``: the heading changes faster than ``max_yaw_rate_dps``;
* ``size``: a box's own size (KITTI labels carry one per box) differs from the box before by more
  than ``max_size_change`` in width, length or height;
* ``reenters``: the box is in a camera's view again after frames without a box or with its box
  out of every camera's view.

A reported frame starts a new piece of the track: the extrapolation starts over there, and the
reconstruction's pose refinement does not link the boxes across it (``source.tracks.reported``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene.poses import Pose, yaw_of
from ..scene.visibility import box_corners_world, box_in_frustum, vehicle_local_box


@dataclass(frozen=True)
class TrackChecks:
    jump_m: float = 3.0  # off the extrapolated motion (a tracker's decimetres of noise never are)
    max_accel_mps2: float = 10.0  # about 1 g: what a real car's motion may add to the extrapolation
    max_speed_mps: float = 70.0  # 250 km/h
    max_yaw_rate_dps: float = 180.0
    max_size_change: float = 0.3  # relative


@dataclass(frozen=True)
class TrackReport:
    actor: str
    frame: int  # the package frame of the box reported
    kind: str  # jump, turn, size, reenters
    message: str

    def to_json(self) -> dict:
        return {"actor": self.actor, "frame": self.frame, "kind": self.kind, "message": self.message}


def in_view(m, pose: Pose, wlh, frame: int) -> bool:
    """Whether the box at ``pose`` can be seen by any of the package's cameras at ``frame``."""
    lo, hi = vehicle_local_box(wlh)
    corners = box_corners_world(lo, hi, pose.R, pose.translation)
    return any(box_in_frustum(corners, c.frames[frame].world_to_camera, c.frames[frame].K, c.width, c.height)
               for c in m.cameras)


def check_track(actor: str, poses: list[Pose | None], times, seen: list[bool], sizes: dict[int, np.ndarray],
                checks: TrackChecks = TrackChecks()) -> list[TrackReport]:
    """The reports of one track: ``poses`` per package frame (world, None: no box), ``times`` the
    frames' timestamps (s), ``seen`` per frame whether its box is in a camera's view, ``sizes``
    the boxes' own sizes by frame where the tracks give one per box."""
    back = reentries(seen)
    out = [TrackReport(actor, f, "reenters", f"{actor} frame {f}: back in view after frames {a + 1}-{f - 1} out of "
                                             "the images") for f, a in back.items()]
    frames = [f for f, p in enumerate(poses) if p is not None]
    velocity = None  # of the last plausible step, m/s; None at a track's start and after a report
    for a, b in zip(frames, frames[1:]):
        dt = max(float(times[b] - times[a]), 1e-6)
        step = poses[b].translation - poses[a].translation
        found = []
        off = None if velocity is None or b != a + 1 or b in back else float(np.linalg.norm(step - velocity * dt))
        if off is not None and off > checks.jump_m + 0.5 * checks.max_accel_mps2 * dt * dt:
            found.append(("jump", f"box {off:.1f} m from where its motion puts it (frame {a} to {b})"))
        elif np.linalg.norm(step) / dt > checks.max_speed_mps:
            found.append(("jump", f"box moved {np.linalg.norm(step):.1f} m in {dt:.2f} s (frame {a} to {b})"))
        turn = abs(np.degrees(np.angle(np.exp(1j * (yaw_of(poses[b].rotation) - yaw_of(poses[a].rotation))))))
        if turn > checks.max_yaw_rate_dps * dt:
            found.append(("turn", f"heading changed {turn:.0f} degrees in {dt:.2f} s (frame {a} to {b})"))
        if a in sizes and b in sizes:
            change = float(np.max(np.abs(sizes[b] / sizes[a] - 1.0)))
            if change > checks.max_size_change:
                found.append(("size", f"box size changed {100 * change:.0f} % (frame {a} to {b}): "
                                      "another vehicle under the same id?"))
        out += [TrackReport(actor, b, kind, f"{actor} frame {b}: {text}") for kind, text in found]
        velocity = None if found or b in back else step / dt
    return sorted(out, key=lambda r: r.frame)


def reentries(seen: list[bool]) -> dict[int, int]:
    """{frame back in view: the last frame in view before it} of a track's ``seen`` flags."""
    out, last = {}, None
    for f, s in enumerate(seen):
        if s:
            if last is not None and f > last + 1:
                out[f] = last
            last = f
    return out
