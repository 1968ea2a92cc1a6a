"""Read SUMO's floating car data (FCD) into per-vehicle tracks of box centres and headings.

FCD rows are ``<timestep time><vehicle id x y angle speed type .../>``. SUMO's ``x, y`` is the
FRONT bumper in net coordinates and ``angle`` is degrees clockwise from north (+Y). The box
centre in the scene frame is ``front - net_offset - (length / 2) * heading`` with
``yaw = radians(90 - angle)`` (counter-clockwise from +X). Only the standard library and numpy.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass
class Track:
    vehicle: str
    vtype: str
    times: np.ndarray  # [T] seconds of simulation time
    centre: np.ndarray  # [T, 2] box centre, scene frame
    yaw: np.ndarray  # [T] radians counter-clockwise from +X
    speed: np.ndarray  # [T] m/s


def yaw_from_sumo_angle(angle_deg) -> np.ndarray:
    return np.radians(90.0 - np.asarray(angle_deg, dtype=np.float64))


def read_fcd(path: Path, lengths: dict[str, float], net_offset=(0.0, 0.0)) -> dict[str, Track]:
    """Tracks by vehicle id; ``lengths`` maps vehicle type id -> length in metres."""
    rows: dict[str, list[tuple[float, float, float, float, float]]] = {}
    types: dict[str, str] = {}
    time = 0.0
    for event, elem in ET.iterparse(path, events=("start", "end")):
        if event == "start" and elem.tag == "timestep":
            time = float(elem.get("time"))
        elif event == "end" and elem.tag == "vehicle":
            vid = elem.get("id")
            rows.setdefault(vid, []).append((time, float(elem.get("x")), float(elem.get("y")),
                                             float(elem.get("angle")), float(elem.get("speed"))))
            types.setdefault(vid, elem.get("type"))
        elif event == "end" and elem.tag == "timestep":
            elem.clear()
    offset = np.asarray(net_offset, dtype=np.float64)
    tracks = {}
    for vid, r in rows.items():
        a = np.asarray(r, dtype=np.float64)
        yaw = yaw_from_sumo_angle(a[:, 3])
        heading = np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
        centre = a[:, 1:3] - offset - 0.5 * lengths[types[vid]] * heading
        tracks[vid] = Track(vid, types[vid], a[:, 0], centre, yaw, a[:, 4])
    return tracks
