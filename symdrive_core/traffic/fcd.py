"""SUMO floating car data (FCD): the one reader, for ``symdrive traffic`` and the add-on alike.

FCD gives, per ``<timestep time=...>``, one ``<vehicle id x y [z] angle speed type .../>`` per
vehicle. SUMO's ``x, y`` is the middle of the FRONT bumper in network coordinates and ``angle`` a
compass heading: degrees clockwise from north (+Y). Our vehicle frame has its origin at the box
centre and faces +X, so ``yaw = radians(90 - angle)`` (counter-clockwise from +X) and the centre
lies half a length behind the bumper: ``centre = bumper - net_offset - (length / 2) * heading``
(:meth:`Track.centre`, the only place that rule is written). Standard library and numpy only:
the add-on vendors this module.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import check_regular

TIME_EPS = 1e-6  # a time this close to a track's ends is inside it (FCD times are rounded)


@dataclass
class Track:
    """One vehicle's FCD samples, in time order."""

    vehicle: str
    vtype: str  # SUMO vehicle type ("" when the file names none)
    times: np.ndarray  # [T] seconds of simulation time
    bumper: np.ndarray  # [T, 2] middle of the front bumper, network coordinates
    z: np.ndarray  # [T] metres (0 where the network is flat and FCD has no z)
    angle_deg: np.ndarray  # [T] SUMO heading
    speed: np.ndarray  # [T] m/s

    @property
    def yaw(self) -> np.ndarray:
        """Heading about +Z from +X, unwrapped so it interpolates without 360-degree jumps."""
        return np.unwrap(yaw_from_sumo_angle(self.angle_deg))

    def centre(self, length: float, net_offset=(0.0, 0.0)) -> np.ndarray:
        """[T, 2] box centre in the scene frame, for a vehicle ``length`` metres long."""
        yaw = self.yaw
        heading = np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
        return self.bumper - np.asarray(net_offset, dtype=np.float64) - 0.5 * float(length) * heading


def yaw_from_sumo_angle(angle_deg) -> np.ndarray:
    return np.radians(90.0 - np.asarray(angle_deg, dtype=np.float64))


def yaw_to_sumo_angle(yaw_rad) -> np.ndarray:
    return np.mod(90.0 - np.degrees(np.asarray(yaw_rad, dtype=np.float64)), 360.0)


def sample_track(track: Track, times, length: float = 0.0,
                 net_offset=(0.0, 0.0)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(box centre [N, 3], yaw [N], present [N]) at ``times``: centre and unwrapped yaw linear
    between samples, held at the ends; ``present`` is False before the vehicle departs and after
    it arrives."""
    t = np.asarray(times, dtype=np.float64)
    present = (t >= track.times[0] - TIME_EPS) & (t <= track.times[-1] + TIME_EPS)
    centre = track.centre(length, net_offset)
    xy = np.stack([np.interp(t, track.times, centre[:, i]) for i in range(2)], axis=1)
    z = np.interp(t, track.times, track.z)
    return np.concatenate([xy, z[:, None]], axis=1), np.interp(t, track.times, track.yaw), present


def _number(path: Path, el: ET.Element, key: str, where: str, default: float | None = None) -> float:
    raw = el.get(key)
    if raw is None:
        if default is not None:
            return default
        raise InputError(path, "required attribute is missing", f"{where}.{key}")
    try:
        value = float(raw)
    except ValueError:
        raise InputError(path, f"expected a number, got {raw!r}", f"{where}.{key}") from None
    if not math.isfinite(value):
        raise InputError(path, f"expected a finite number, got {raw!r}", f"{where}.{key}")
    return value


def read_fcd(path: str | os.PathLike) -> dict[str, Track]:
    """All vehicle tracks of an FCD file; errors name the file and the timestep/vehicle field."""
    path = Path(path)
    check_regular(path, "fcd-export")  # a folder (no file chosen) or a FIFO: one line, not a traceback
    rows: dict[str, list[tuple[float, ...]]] = {}
    types: dict[str, str] = {}
    time = None
    seen_root = False
    try:
        for event, el in ET.iterparse(path, events=("start", "end")):
            if event == "start":
                if not seen_root:
                    seen_root = True
                    if el.tag != "fcd-export":
                        raise InputError(path, f"root element is <{el.tag}>, expected <fcd-export>", "fcd-export")
                elif el.tag == "timestep":
                    time = _number(path, el, "time", "timestep")
                continue
            if el.tag == "vehicle":
                if time is None:
                    raise InputError(path, "<vehicle> outside a <timestep>", "vehicle")
                vid = el.get("id")
                if not vid:
                    raise InputError(path, "required attribute is missing", f"timestep[time={time}].vehicle.id")
                where = f"timestep[time={time}].vehicle[id={vid}]"
                rows.setdefault(vid, []).append((time, _number(path, el, "x", where), _number(path, el, "y", where),
                                                 _number(path, el, "z", where, 0.0),
                                                 _number(path, el, "angle", where),
                                                 _number(path, el, "speed", where, 0.0)))
                types.setdefault(vid, el.get("type") or "")
            elif el.tag == "timestep":
                time = None
                el.clear()
    except FileNotFoundError:
        raise InputError(path, "file not found") from None
    except ET.ParseError as exc:
        raise InputError(path, f"not valid XML: {exc}") from None
    tracks = {}
    for vid, r in rows.items():
        a = np.array(r, dtype=np.float64)
        a = a[np.argsort(a[:, 0], kind="stable")]
        if np.any(np.diff(a[:, 0]) <= 0):
            raise InputError(path, f"vehicle {vid!r} appears twice in one timestep", "timestep.vehicle")
        tracks[vid] = Track(vid, types[vid], a[:, 0], a[:, 1:3], a[:, 3], a[:, 4], a[:, 5])
    return tracks
