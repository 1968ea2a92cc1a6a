"""SUMO traffic in lock-step with the ego: every step the ego is pushed into SUMO over TraCI
(``moveToXY`` and its speed), SUMO advances one step, and its vehicles are read back, so they
brake and change lanes around the ego.

Reuses :mod:`symdrive_core.traffic`: the SUMO network lies on the package's road
(:func:`~symdrive_core.traffic.network.build_network`; a package without a road gets a one-lane
road along its corridor), SUMO starts under :func:`~symdrive_core.traffic.sumo_run.traci_session`
(a wall-clock limit, never outliving the run) and positions convert as in
:mod:`~symdrive_core.traffic.fcd` (SUMO gives the front bumper and a compass angle). In SUMO mode
the package's own actors are not replayed; they are the vehicle models SUMO's vehicles wear
(cycled), and ``sumo_vehicles`` of them are placed on free slots of the lanes by the seed.
"""

from __future__ import annotations

import contextlib
import tempfile
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..rotations import quat_from_yaw
from ..scene.poses import Pose
from ..scene.road import Road
from ..traffic.demand import MIN_GAP_M
from ..traffic.fcd import yaw_from_sumo_angle
from ..traffic.network import build_network, lane_length
from ..traffic.sumo_run import traci_session
from .traffic import ActorState

EGO = "ego"
SLOT_M = 9.0  # spacing of the places vehicles may start at
EGO_CLEAR_M = 12.0  # no vehicle starts this close to the ego along its lane


class SumoTraffic:
    reactive = True

    def __init__(self, env, config):
        self.env, self.config = env, config
        area = env.area
        self.road = area.road or Road(np.column_stack([area.line, area.line_z]), 1, area.lane_width)
        self.templates = [(a.id, np.asarray(a.wlh if a.wlh is not None else config.default_actor_wlh, float))
                          for a in env.manifest.actors if a.splats] or [(None, np.asarray(config.default_actor_wlh))]
        self._stack: contextlib.ExitStack | None = None
        self.conn = None
        self.types: dict[str, tuple[str | None, np.ndarray]] = {}

    def close(self) -> None:
        if self._stack is not None:
            self._stack.close()
        self._stack, self.conn = None, None

    def reset(self, seed: int | None = None) -> None:
        self.close()
        stack = contextlib.ExitStack()
        work = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="symdrive-sim-")))
        net = build_network(self.road, self.config.sumo_speed, work)
        root = ET.Element("routes")
        ego_w, ego_l, ego_h = (f"{v:.4f}" for v in self.env.wlh)
        ET.SubElement(root, "vType", id=EGO, length=ego_l, width=ego_w, height=ego_h, minGap=f"{MIN_GAP_M}")
        for k, (aid, wlh) in enumerate(self.templates):
            w, l, h = (f"{v:.4f}" for v in wlh)
            ET.SubElement(root, "vType", id=f"t{k}", length=l, width=w, height=h, minGap=f"{MIN_GAP_M}",
                          lcStrategic="1", lcCooperative="1", lcSpeedGain="1")
        for edge in net.edges:
            ET.SubElement(root, "route", id=edge, edges=edge)
        ET.ElementTree(root).write(work / "routes.rou.xml")
        args = ["-n", net.path.name, "-r", "routes.rou.xml", "--step-length", f"{self.env.dt}",
                "--seed", str(int(seed or 0)), "--collision.action", "none", "--time-to-teleport", "-1",
                "--no-step-log", "true", "--no-warnings", "true", "--duration-log.disable", "true",
                "--eager-insert", "true"]
        self.conn = conn = stack.enter_context(traci_session(args, self.config.sumo_timeout_s, work))
        self._stack = stack
        self.offset = net.offset
        # The ego first, where it stands.
        e = self.env.ego
        edge, pos, lane = conn.simulation.convertRoad(*self._front(e.x, e.y, e.yaw))
        conn.vehicle.add(EGO, routeID="forward", typeID=EGO, departLane=str(max(lane, 0)),
                         departPos=f"{max(pos, 0.0):.3f}", departSpeed=f"{e.v:.3f}")
        conn.vehicle.setSpeedMode(EGO, 0)
        conn.vehicle.setLaneChangeMode(EGO, 0)
        # Traffic on free slots, chosen by the seed.
        rng = np.random.default_rng(seed)
        slots = []
        for ed, lanes in net.edges.items():
            length = lane_length(net, ed)
            for ln in range(lanes):
                for p in np.arange(SLOT_M, length, SLOT_M):
                    if ed == edge and ln == lane and abs(p - pos) < EGO_CLEAR_M:
                        continue
                    slots.append((ed, ln, float(p)))
        n = min(self.config.sumo_vehicles, len(slots))
        if n < self.config.sumo_vehicles:
            warnings.warn(f"SUMO traffic: {n} of {self.config.sumo_vehicles} vehicles placed: the road has room for "
                          f"{len(slots)} ({SLOT_M:g} m apart, none within {EGO_CLEAR_M:g} m of the ego)", stacklevel=2)
        self.types = {}
        chosen = rng.choice(len(slots), size=n, replace=False) if n else []
        kinds = rng.integers(len(self.templates), size=n)
        # Downstream first: each vehicle then enters behind one already there.
        order = sorted(range(n), key=lambda j: -slots[chosen[j]][2])
        for k in order:
            ed, ln, p = slots[chosen[k]]
            t = int(kinds[k])
            vid = f"v{k}"
            conn.vehicle.add(vid, routeID=ed, typeID=f"t{t}", departLane=str(ln), departPos=f"{p:.3f}",
                             departSpeed="max")
            self.types[vid] = self.templates[t]
        self._push(e)
        conn.simulationStep()

    def _front(self, x, y, yaw):
        front = np.array([x, y]) + 0.5 * self.env.wlh[1] * np.array([np.cos(yaw), np.sin(yaw)])
        return float(front[0] + self.offset[0]), float(front[1] + self.offset[1])

    def _push(self, e) -> None:
        fx, fy = self._front(e.x, e.y, e.yaw)
        self.conn.vehicle.moveToXY(EGO, "", -1, fx, fy, angle=float(90.0 - np.degrees(e.yaw)), keepRoute=2)
        self.conn.vehicle.setSpeed(EGO, float(e.v))

    def step(self, t: float, ego) -> None:
        if EGO in self.conn.vehicle.getIDList():
            self._push(ego)
        self.conn.simulationStep()

    def states(self, t: float, dt: float = 0.1) -> list[ActorState]:
        out = []
        conn = self.conn
        for vid in conn.vehicle.getIDList():
            if vid == EGO or vid not in self.types:
                continue
            asset, wlh = self.types[vid]
            yaw = float(yaw_from_sumo_angle(conn.vehicle.getAngle(vid)))
            heading = np.array([np.cos(yaw), np.sin(yaw)])
            centre = np.asarray(conn.vehicle.getPosition(vid)) - self.offset - 0.5 * wlh[1] * heading
            z = float(self.road.ground_height(centre[None])[0]) + 0.5 * wlh[2]
            pose = Pose(np.array([centre[0], centre[1], z]), quat_from_yaw(yaw))
            out.append(ActorState(vid, pose, wlh, conn.vehicle.getSpeed(vid) * heading, asset))
        return out
