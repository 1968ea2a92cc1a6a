"""Execute manoeuvres through TraCI, step by step, so the rest of the traffic reacts (closed loop).

Each manoeuvre is a small state machine advanced after every simulation step. The chosen
vehicle is commanded (speed, lane-change request, lateral speed); every other vehicle keeps
following SUMO's car-following and lane-change models and so brakes or yields in response.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import SymDriveError
from ..scene.road import project_onto
from .fcd import yaw_from_sumo_angle
from .manoeuvre_spec import Manoeuvre

# Lane-change modes (bits 8-9 say how a TraCI request treats others; bits 0-7 = 0 switch off the
# vehicle's own strategic, cooperative, speed-gain and keep-right changes, so it stays put after).
LC_MODE_AGGRESSIVE = 1 << 8  # only avoid immediate collisions
LC_MODE_POLITE = 2 << 8  # wait for the gaps other drivers need
ALIGN_GAIN = 0.8  # 1/s: how fast a cut-in closes the error to its planned gap
ALIGN_MAX_DV = 4.0  # m/s: largest speed difference to the vehicle being cut off while aligning
ALIGN_TOLERANCE_M = 0.5
ALIGN_TIMEOUT_S = 10.0
CHANGE_TIMEOUT_S = 10.0
LATERAL_DONE_M = 0.1  # m: a lane change is done once the box centre is this close to the lane centre


class ManoeuvreError(SymDriveError):
    """A manoeuvre could not be carried out as specified."""


@dataclass
class _State:
    spec: Manoeuvre
    phase: str = "waiting"  # waiting -> (align ->) change | brake -> hold -> done
    vehicle: str | None = None
    target_lane: int | None = None
    other: str | None = None  # the vehicle being cut off
    deadline: float = 0.0
    v0: float = 0.0
    t0: float = 0.0
    log: dict = field(default_factory=dict)


class Director:
    """Runs the manoeuvres; ``time_offset`` maps scene time to simulation time (sim = scene + offset)."""

    def __init__(self, manoeuvres: list[Manoeuvre], time_offset: float, net_offset, lane_width: float):
        self.states = [_State(m) for m in manoeuvres]
        self.time_offset = time_offset
        self.net_offset = np.asarray(net_offset, dtype=np.float64)
        self.lane_width = lane_width

    def step(self, conn, t: float) -> None:
        for s in self.states:
            if s.phase == "waiting" and t + 1e-9 >= s.spec.at + self.time_offset:
                self._start(conn, s, t)
            elif s.phase == "align":
                self._align(conn, s, t)
            elif s.phase == "change":
                self._check_change(conn, s, t)
            elif s.phase in ("brake", "hold"):
                self._brake(conn, s, t)

    def report(self) -> list[dict]:
        """One entry per manoeuvre; raises if any did not finish within the simulated time."""
        unfinished = [s for s in self.states if s.phase not in ("done", "hold")]
        if unfinished:
            s = unfinished[0]
            raise ManoeuvreError(f"{s.spec.kind} of {s.vehicle or s.spec.vehicle} at {s.spec.at:g} s did not "
                                 f"finish before the simulation ended (phase: {s.phase}); "
                                 "start it earlier or simulate longer")
        return [s.log for s in self.states]

    # ------------------------------------------------------------ phases

    def _start(self, conn, s: _State, t: float) -> None:
        s.vehicle = self._resolve(conn, s.spec, t)
        s.t0 = t
        s.log = {"kind": s.spec.kind, "vehicle": s.vehicle, "started": self._scene(t)}
        if s.spec.kind == "hard_brake":
            v, decel = conn.vehicle.getSpeed(s.vehicle), s.spec.deceleration
            conn.vehicle.setDecel(s.vehicle, max(decel, conn.vehicle.getDecel(s.vehicle)))
            conn.vehicle.setEmergencyDecel(s.vehicle, max(decel, conn.vehicle.getEmergencyDecel(s.vehicle)))
            s.v0, s.phase = v, "brake"
            s.log["speed_before"] = round(v, 3)
            self._brake(conn, s, t)
            return
        s.target_lane = self._adjacent_lane(conn, s, t)
        if s.spec.kind == "cut_in":
            s.other = self._cut_off_vehicle(conn, s, t)
            s.log["cut_off"] = s.other
            s.phase, s.deadline = "align", t + ALIGN_TIMEOUT_S
            self._align(conn, s, t)
        else:
            self._request_change(conn, s, t, s.spec.aggressive)

    def _resolve(self, conn, spec: Manoeuvre, t: float) -> str:
        present = list(conn.vehicle.getIDList())
        if isinstance(spec.vehicle, str):
            if spec.vehicle not in present:
                listed = ", ".join(sorted(present)[:12]) + (" ..." if len(present) > 12 else "")
                raise ManoeuvreError(f"{spec.kind}: vehicle {spec.vehicle!r} is not on the road at "
                                     f"{spec.at:g} s (present: {listed or 'none'})")
            return spec.vehicle
        if not present:
            raise ManoeuvreError(f"{spec.kind}: no vehicle on the road at {spec.at:g} s")
        centres = np.array([self._centre(conn, v) for v in present])
        return present[int(np.argmin(np.linalg.norm(centres - np.asarray(spec.vehicle), axis=1)))]

    def _centre(self, conn, vid: str) -> np.ndarray:
        yaw = float(yaw_from_sumo_angle(conn.vehicle.getAngle(vid)))
        front = np.asarray(conn.vehicle.getPosition(vid)) - self.net_offset
        return front - 0.5 * conn.vehicle.getLength(vid) * np.array([np.cos(yaw), np.sin(yaw)])

    def _adjacent_lane(self, conn, s: _State, t: float) -> int:
        lane = conn.vehicle.getLaneIndex(s.vehicle)
        lanes = conn.edge.getLaneNumber(conn.vehicle.getRoadID(s.vehicle))
        target = lane + (1 if s.spec.direction == "left" else -1)
        if not 0 <= target < lanes:
            raise ManoeuvreError(f"{s.spec.kind}: {s.vehicle} is in the {s.spec.direction}most lane at "
                                 f"{self._scene(t):g} s; there is no lane on its {s.spec.direction}")
        return target

    def _cut_off_vehicle(self, conn, s: _State, t: float) -> str:
        lane_id = f"{conn.vehicle.getRoadID(s.vehicle)}_{s.target_lane}"
        own = conn.vehicle.getLanePosition(s.vehicle)
        behind = [(conn.vehicle.getLanePosition(v), v) for v in conn.lane.getLastStepVehicleIDs(lane_id)]
        behind = [(p, v) for p, v in behind if p < own]
        if not behind:
            raise ManoeuvreError(f"cut_in: no vehicle behind {s.vehicle} in the lane on its {s.spec.direction} "
                                 f"at {self._scene(t):g} s to cut in front of")
        return max(behind)[1]

    def _gap_ahead_of_other(self, conn, s: _State) -> float:
        rear = conn.vehicle.getLanePosition(s.vehicle) - conn.vehicle.getLength(s.vehicle)
        return rear - conn.vehicle.getLanePosition(s.other)

    def _align(self, conn, s: _State, t: float) -> None:
        if s.other not in conn.vehicle.getIDList():
            raise ManoeuvreError(f"cut_in: {s.other} left the road before {s.vehicle} could cut in")
        error = self._gap_ahead_of_other(conn, s) - s.spec.gap
        if abs(error) <= ALIGN_TOLERANCE_M or t >= s.deadline:
            conn.vehicle.setSpeed(s.vehicle, -1.0)  # back to its own car-following
            s.log["gap_at_change_m"] = round(error + s.spec.gap, 3)
            self._request_change(conn, s, t, aggressive=True)
            return
        v_other = conn.vehicle.getSpeed(s.other)
        dv = float(np.clip(-ALIGN_GAIN * error, -ALIGN_MAX_DV, ALIGN_MAX_DV))
        conn.vehicle.setSpeed(s.vehicle, max(0.0, v_other + dv))

    def _request_change(self, conn, s: _State, t: float, aggressive: bool) -> None:
        conn.vehicle.setLaneChangeMode(s.vehicle, LC_MODE_AGGRESSIVE if aggressive else LC_MODE_POLITE)
        conn.vehicle.setMaxSpeedLat(s.vehicle, self.lane_width / s.spec.duration)
        conn.vehicle.changeLane(s.vehicle, s.target_lane, CHANGE_TIMEOUT_S)
        s.phase, s.deadline = "change", t + CHANGE_TIMEOUT_S
        s.log["change_requested"] = self._scene(t)

    def _check_change(self, conn, s: _State, t: float) -> None:
        if s.vehicle not in conn.vehicle.getIDList():
            raise ManoeuvreError(f"{s.spec.kind}: {s.vehicle} left the road during its lane change")
        if self._off_target_lane(conn, s) < LATERAL_DONE_M:
            s.phase = "done"
            s.log["finished"] = self._scene(t)
        elif t >= s.deadline:
            raise ManoeuvreError(f"{s.spec.kind}: {s.vehicle} found no gap to change lanes within "
                                 f"{CHANGE_TIMEOUT_S:g} s (make it aggressive or pick another time)")

    def _off_target_lane(self, conn, s: _State) -> float:
        """Sideways distance of the box centre from the target lane's centre line."""
        lane_id = f"{conn.vehicle.getRoadID(s.vehicle)}_{s.target_lane}"
        shape = np.asarray(conn.lane.getShape(lane_id), dtype=np.float64)[:, :2] - self.net_offset
        lateral, _, _ = project_onto(shape, self._centre(conn, s.vehicle)[None])
        return abs(float(lateral[0]))

    def _brake(self, conn, s: _State, t: float) -> None:
        if s.vehicle not in conn.vehicle.getIDList():
            s.phase = "done"  # left the road while braking or holding: nothing more to command
            return
        target = s.spec.speed
        if s.phase == "brake":
            command = max(target, s.v0 - s.spec.deceleration * (t - s.t0))
            conn.vehicle.setSpeed(s.vehicle, command)
            if command <= target:
                s.phase, s.deadline = "hold", t + s.spec.hold
                s.log["reached_speed"] = self._scene(t)
        elif t >= s.deadline:
            conn.vehicle.setSpeed(s.vehicle, -1.0)
            s.phase = "done"
            s.log["released"] = self._scene(t)

    def _scene(self, t: float) -> float:
        return round(t - self.time_offset, 4)
