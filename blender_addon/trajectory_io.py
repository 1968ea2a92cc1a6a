"""SUMO floating-car-data (FCD) trajectories, read with the standard library and numpy only.

FCD gives, per ``<timestep time=...>``, one ``<vehicle id x y [z] angle speed .../>`` per
vehicle. SUMO's ``x, y`` is the middle of the FRONT bumper and ``angle`` is a compass heading:
degrees clockwise from north (+Y). Our vehicle frame has its origin at the box centre and
faces +X, so ``yaw = radians(90 - angle)`` and the centre lies half a length behind the bumper.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .core import errors


@dataclass
class Track:
    """One vehicle's FCD samples, in time order."""

    vehicle_id: str
    time: np.ndarray  # [T] seconds
    xy: np.ndarray  # [T, 2] front bumper, metres
    z: np.ndarray  # [T] metres (0 where the network is flat and FCD has no z)
    angle_deg: np.ndarray  # [T] SUMO heading
    speed: np.ndarray  # [T] m/s

    @property
    def yaw(self) -> np.ndarray:
        """Heading about +Z from +X, unwrapped so it interpolates without 360-degree jumps."""
        return np.unwrap(sumo_angle_to_yaw(self.angle_deg))


def sumo_angle_to_yaw(angle_deg) -> np.ndarray:
    return np.radians(90.0 - np.asarray(angle_deg, dtype=np.float64))


def yaw_to_sumo_angle(yaw_rad) -> np.ndarray:
    return np.mod(90.0 - np.degrees(np.asarray(yaw_rad, dtype=np.float64)), 360.0)


def _number(path: Path, el: ET.Element, key: str, where: str, default: float | None = None) -> float:
    raw = el.get(key)
    if raw is None:
        if default is not None:
            return default
        raise errors.InputError(path, "required attribute is missing", f"{where}.{key}")
    try:
        value = float(raw)
    except ValueError:
        raise errors.InputError(path, f"expected a number, got {raw!r}", f"{where}.{key}") from None
    if not math.isfinite(value):
        raise errors.InputError(path, f"expected a finite number, got {raw!r}", f"{where}.{key}")
    return value


def read_fcd(path: str | os.PathLike) -> dict[str, Track]:
    """All vehicle tracks of an FCD file; errors name the file and the timestep/vehicle field."""
    path = Path(path)
    rows: dict[str, list[tuple[float, ...]]] = {}
    time = None
    seen_root = False
    try:
        for event, el in ET.iterparse(path, events=("start", "end")):
            if event == "start":
                if not seen_root:
                    seen_root = True
                    if el.tag != "fcd-export":
                        raise errors.InputError(
                            path, f"root element is <{el.tag}>, expected <fcd-export>", "fcd-export"
                        )
                elif el.tag == "timestep":
                    time = _number(path, el, "time", "timestep")
                continue
            if el.tag == "vehicle":
                if time is None:
                    raise errors.InputError(path, "<vehicle> outside a <timestep>", "vehicle")
                vid = el.get("id")
                if not vid:
                    raise errors.InputError(
                        path, "required attribute is missing", f"timestep[time={time}].vehicle.id"
                    )
                where = f"timestep[time={time}].vehicle[id={vid}]"
                rows.setdefault(vid, []).append(
                    (
                        time,
                        _number(path, el, "x", where),
                        _number(path, el, "y", where),
                        _number(path, el, "z", where, 0.0),
                        _number(path, el, "angle", where),
                        _number(path, el, "speed", where, 0.0),
                    )
                )
            elif el.tag == "timestep":
                time = None
                el.clear()
    except FileNotFoundError:
        raise errors.InputError(path, "file not found") from None
    except ET.ParseError as exc:
        raise errors.InputError(path, f"not valid XML: {exc}") from None
    tracks = {}
    for vid, r in rows.items():
        a = np.array(r, dtype=np.float64)
        a = a[np.argsort(a[:, 0], kind="stable")]
        if np.any(np.diff(a[:, 0]) <= 0):
            raise errors.InputError(
                path, f"vehicle {vid!r} appears twice in one timestep", "timestep.vehicle"
            )
        tracks[vid] = Track(vid, a[:, 0], a[:, 1:3], a[:, 3], a[:, 4], a[:, 5])
    return tracks


def sample_track(track: Track, times, length: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vehicle centre [N, 3] and yaw [N] at ``times``, plus a mask of times inside the track.

    Positions and (unwrapped) yaw are interpolated linearly between FCD samples; ``length``
    moves the point from the front bumper back to the box centre. Outside the track the mask
    is False (the vehicle has not departed yet or has arrived).
    """
    t = np.asarray(times, dtype=np.float64)
    inside = (t >= track.time[0] - 1e-9) & (t <= track.time[-1] + 1e-9)
    yaw = np.interp(t, track.time, track.yaw)
    x = np.interp(t, track.time, track.xy[:, 0]) - 0.5 * length * np.cos(yaw)
    y = np.interp(t, track.time, track.xy[:, 1]) - 0.5 * length * np.sin(yaw)
    z = np.interp(t, track.time, track.z)
    return np.stack([x, y, z], axis=1), yaw, inside
