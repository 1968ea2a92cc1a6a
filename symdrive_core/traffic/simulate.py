"""One traffic simulation: road -> SUMO network -> demand -> SUMO run (TraCI when manoeuvres) -> tracks.

Timeline: SUMO simulates ``seconds`` seconds; the package's frames are sampled from the LAST
part of the run (frame ``i`` at simulation time ``seconds - (t_last - t_i)``), so the seconds
before the first frame let traffic settle.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..scene.road import Road
from .assets import Asset
from .demand import write_routes
from .fcd import Track, read_fcd
from .manoeuvre_spec import Manoeuvre
from .manoeuvres import Director
from .network import Network, build_network, lane_length
from .sumo_run import run_tool, traci_session

DEFAULT_SPEED = 13.89  # m/s, 50 km/h
STEP_S = 0.1
LANE_CHANGE_S = 3.0  # duration of SUMO's own (non-scripted) lane changes
MAX_DEPART_DELAY_S = 2.0  # inflow vehicles that find no room for this long are dropped


@dataclass
class TrafficOptions:
    density: float  # vehicles per km per lane
    seconds: float
    seed: int = 0
    speed: float = DEFAULT_SPEED  # lane speed limit in m/s; 0 = standing traffic
    manoeuvres: list[Manoeuvre] = field(default_factory=list)
    timeout: float = 300.0


@dataclass
class TrafficRun:
    tracks: dict[str, Track]  # as SUMO wrote them: front bumpers in network coordinates
    network: Network
    vehicles_at_start: int
    sumo_seconds: float  # wall time of the SUMO run alone
    time_offset: float  # simulation time = scene time + time_offset
    manoeuvres: list[dict]


def check_inputs(road: Road, frame_times: np.ndarray, assets: list[Asset], opt: TrafficOptions, where: str) -> None:
    if not opt.density >= 0:
        raise InputError(where, f"--density must be >= 0 vehicles per km per lane, got {opt.density}")
    if not opt.speed >= 0:
        raise InputError(where, f"--speed must be >= 0 m/s, got {opt.speed}")
    span = float(frame_times[-1] - frame_times[0])
    if not opt.seconds > 0 or opt.seconds + 1e-9 < span:
        raise InputError(where, f"--seconds must cover the package's frames ({span:g} s), got {opt.seconds}")
    if opt.density > 0 and not assets:
        raise InputError(where, "no vehicle assets: pass --assets DIR (folders with wlh.json)")
    longest = max(assets, key=lambda a: a.length, default=None)
    if opt.density > 0 and longest.length >= road.length:
        raise InputError(longest.folder / "wlh.json", f"vehicle is {longest.length:g} m long, the road only "
                                                      f"{road.length:g} m: no vehicle fits")
    for m in opt.manoeuvres:
        if not frame_times[0] - 1e-9 <= m.at <= frame_times[-1] + 1e-9:
            raise InputError(where, f"{m.kind} at {m.at:g} s is outside the frames "
                                    f"({frame_times[0]:g} to {frame_times[-1]:g} s)")


def simulate(road: Road, frame_times: np.ndarray, assets: list[Asset], opt: TrafficOptions,
             workdir: Path, where: str = "traffic", progress: bool = True) -> TrafficRun:
    """Run SUMO in ``workdir`` (network, routes and FCD are left there). ``progress``: a bar over
    simulated seconds when manoeuvres step SUMO through TraCI (a plain run is one SUMO call)."""
    frame_times = np.asarray(frame_times, dtype=np.float64)
    check_inputs(road, frame_times, assets, opt, where)
    net = build_network(road, opt.speed, workdir)
    lanes = {edge: (count, lane_length(net, edge)) for edge, count in net.edges.items()}
    rng = np.random.default_rng(opt.seed)
    at_start = write_routes(workdir / "routes.rou.xml", assets, lanes, opt.density, opt.speed, opt.seconds,
                            road.lane_width / LANE_CHANGE_S, rng)
    end = opt.seconds + STEP_S
    args = ["-n", net.path.name, "-r", "routes.rou.xml", "--fcd-output", "fcd.xml", "--precision", "4",
            "--begin", "0", "--end", f"{end:.3f}", "--step-length", f"{STEP_S}", "--seed", str(opt.seed),
            "--lanechange.duration", f"{LANE_CHANGE_S}", "--time-to-teleport", "-1",
            "--max-depart-delay", f"{MAX_DEPART_DELAY_S}", "--collision.action", "warn",
            "--no-step-log", "true", "--no-warnings", "true", "--duration-log.disable", "true"]
    time_offset = opt.seconds - float(frame_times[-1])
    t0 = time.perf_counter()
    log: list[dict] = []
    if opt.manoeuvres:
        from tqdm import tqdm

        director = Director(opt.manoeuvres, time_offset, net.offset, road.lane_width)
        bar = tqdm(total=round(end / STEP_S), desc="traffic", unit="step", disable=not progress)
        with traci_session(args, opt.timeout, workdir) as conn, bar:
            while conn.simulation.getTime() < end - 0.5 * STEP_S:
                conn.simulationStep()
                director.step(conn, conn.simulation.getTime())
                bar.update()
        log = director.report()
    else:
        run_tool("sumo", args, opt.timeout, workdir)
    sumo_seconds = time.perf_counter() - t0
    tracks = read_fcd(workdir / "fcd.xml")
    return TrafficRun(tracks, net, at_start, sumo_seconds, time_offset, log)
