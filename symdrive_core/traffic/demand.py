"""Which vehicles SUMO simulates: the road filled at the start, plus a steady inflow.

``density`` is vehicles per kilometre per lane. At time 0 every lane is filled at about that
spacing (jittered, never closer than SUMO's minimum gap); then each lane's entry receives the
flow that keeps the density, q = density * speed (SUMO inserts no faster than the lane can take,
so very dense starts thin out towards the lane's capacity). Vehicle types are the pool's assets.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from .assets import Asset

MIN_GAP_M = 2.5  # SUMO's default minGap, standstill bumper-to-bumper distance
SPACING_JITTER = 0.3  # relative jitter of the initial spacing
POOL_TYPE = "pool"


def initial_positions(lane_length: float, density: float, lengths: np.ndarray,
                      rng: np.random.Generator) -> list[tuple[float, int]]:
    """Front-bumper positions along one lane and the asset index of each vehicle there.

    ``lengths`` are the pool's vehicle lengths. Vehicles keep at least ``MIN_GAP_M`` between them.
    """
    if density <= 0:
        return []
    spacing = 1000.0 / density
    placed: list[tuple[float, int]] = []
    front = rng.uniform(0.0, spacing)
    while True:
        k = int(rng.integers(len(lengths)))
        earliest = float(lengths[k]) + (placed[-1][0] + MIN_GAP_M if placed else 0.0)
        front = max(front, earliest)
        if front > lane_length:
            return placed
        placed.append((front, k))
        front += spacing * rng.uniform(1.0 - SPACING_JITTER, 1.0 + SPACING_JITTER)


def write_routes(path: Path, assets: list[Asset], lanes: dict[str, tuple[int, float]], density: float,
                 speed: float, seconds: float, lateral_speed: float, rng: np.random.Generator) -> int:
    """Write the routes file; ``lanes`` maps edge id -> (lane count, lane length).

    ``lateral_speed`` (m/s) sets how fast lane changes move sideways; giving it on the vehicle
    types is also what lets TraCI change it per vehicle for a scripted manoeuvre.

    Returns how many vehicles start on the road at time 0.
    """
    root = ET.Element("routes")
    for a in assets:
        w, l, h = (f"{v:.4f}" for v in a.wlh)
        ET.SubElement(root, "vType", id=a.name, length=l, width=w, height=h, minGap=f"{MIN_GAP_M}",
                      maxSpeedLat=f"{lateral_speed:.4f}")
    if assets:
        ET.SubElement(root, "vTypeDistribution", id=POOL_TYPE, vTypes=" ".join(a.name for a in assets))
    lengths = np.array([a.length for a in assets])
    starts = []
    for edge, (count, length) in lanes.items():
        ET.SubElement(root, "route", id=edge, edges=edge)
        for lane in range(count):
            for front, k in initial_positions(length, density, lengths, rng):
                starts.append((edge, lane, front, assets[k].name))
    # Downstream first: each vehicle then enters behind one already there and SUMO gives it the
    # largest speed that is safe behind that leader (inserting upstream first would block the rest).
    starts.sort(key=lambda s: -s[2])
    for n, (edge, lane, front, vtype) in enumerate(starts):
        ET.SubElement(root, "vehicle", id=f"veh{n}", type=vtype, route=edge, depart="0",
                      departLane=str(lane), departPos=f"{front:.3f}", departSpeed="max")
    per_second = density * speed / 1000.0  # vehicles per second per lane
    if per_second > 0 and assets:
        for edge, (count, _) in lanes.items():
            for lane in range(count):
                ET.SubElement(root, "flow", id=f"in_{edge}_lane{lane}", type=POOL_TYPE, route=edge, begin="0",
                              end=f"{seconds:.3f}", probability=f"{min(per_second, 1.0):.6f}",
                              departLane=str(lane), departPos="base", departSpeed="max")
    ET.ElementTree(root).write(path)
    return len(starts)
