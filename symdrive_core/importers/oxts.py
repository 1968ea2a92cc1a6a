"""OXTS GPS/IMU records (KITTI raw's ``oxts/data/NNNNNNNNNN.txt``) -> the IMU's poses.

Each record is one line of 30 numbers (``oxts/dataformat.txt``: lat, lon, alt, roll, pitch, yaw,
then velocities, accelerations, angular rates, accuracies and status flags). The poses follow the
KITTI devkit (``convertOxtsToPose.m``, pykitti's ``pose_from_oxts_packet``) exactly, so a drive
imported here lines up with every tool that reads KITTI: a Mercator projection whose scale
``cos(lat0)`` is the first record's latitude, ``tx = scale * lon * pi * er / 180``,
``ty = scale * er * log(tan((90 + lat) * pi / 360))``, ``tz = alt`` (``er`` the WGS84 equatorial
radius) and the rotation ``Rz(yaw) Ry(pitch) Rx(roll)`` of the IMU axes (x forward, y left, z up).
As pykitti does, the first record's position is subtracted: the world is East-North-Up metres
about where the drive starts, small numbers that float64 keeps to well under a micrometre.

A record is a fix at its own time (``oxts/timestamps.txt``), a few milliseconds from its frame's
image (on ``2011_09_26_drive_0009`` 1 to 11 ms before it, about 7 cm of travel at 38 km/h);
:func:`carried` moves each pose to its image's time by the record's own velocity and angular
rate, where the devkit and pykitti take the fix as it is.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import check_regular
from ..rotations import rotation_vector_matrix
from .calib_text import finite_numbers

FIELDS = 30  # numbers per record
EARTH_RADIUS_M = 6378137.0  # the devkit's er
ALTITUDE_MAX_M = 1e5  # above it no vehicle drives; a fix past it is a corrupt record
RECORD_BYTES_MAX = 1 << 16  # a record is one line of about 250 characters
VELOCITY = slice(8, 11)  # vf, vl, vu: m/s along the IMU's forward, left and up axes
ANGULAR_RATE = slice(20, 23)  # wf, wl, wu: rad/s about the same axes


def read_record(path: Path) -> np.ndarray:
    """The 30 numbers of one OXTS file (one line), or InputError naming the file and the line."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "OXTS record not found (one file per frame)", "oxts")
    if check_regular(path, "oxts").st_size > RECORD_BYTES_MAX:
        raise InputError(path, f"larger than {RECORD_BYTES_MAX} bytes: not an OXTS record", "oxts")
    try:
        lines = [line for line in path.read_text(encoding="utf-8-sig").splitlines() if line.strip()]
    except UnicodeDecodeError as exc:
        raise InputError(path, f"not UTF-8 text (byte {exc.start})", "line 1") from None
    if len(lines) != 1:
        raise InputError(path, f"expected one line of {FIELDS} numbers, got {len(lines)} lines", "line 1")
    record = finite_numbers(lines[0], FIELDS, path, "line 1")
    lat, lon, alt = record[:3]
    if not (-90.0 < lat < 90.0 and -180.0 <= lon <= 180.0 and abs(alt) <= ALTITUDE_MAX_M):
        raise InputError(path, f"lat, lon, alt {lat:g} {lon:g} {alt:g} is no fix on Earth (latitude in (-90, 90), "
                         f"longitude in [-180, 180] degrees, |altitude| <= {ALTITUDE_MAX_M:g} m)", "line 1")
    return record


def euler_rotation(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """The devkit's ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    Ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    Rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    return Rz @ Ry @ Rx


def imu_poses(records: np.ndarray) -> tuple[np.ndarray, dict]:
    """(IMU-to-world poses [N, 4, 4], the projection's record: first fix and Mercator scale)
    from OXTS records [N, 30], in the order given (the first one sets the scale and the origin)."""
    records = np.asarray(records, dtype=np.float64)
    lat, lon, alt = records[:, 0], records[:, 1], records[:, 2]
    scale = np.cos(lat[0] * np.pi / 180.0)
    t = np.stack([scale * lon * np.pi * EARTH_RADIUS_M / 180.0,
                  scale * EARTH_RADIUS_M * np.log(np.tan((90.0 + lat) * np.pi / 360.0)),
                  alt], axis=1)
    poses = np.tile(np.eye(4), (len(records), 1, 1))
    for i, (roll, pitch, yaw) in enumerate(records[:, 3:6]):
        poses[i, :3, :3] = euler_rotation(roll, pitch, yaw)
    poses[:, :3, 3] = t - t[0]
    record = {"lat0_deg": float(lat[0]), "lon0_deg": float(lon[0]), "alt0_m": float(alt[0]),
              "mercator_scale": float(scale), "origin_m": t[0].tolist()}
    return poses, record


def carried(poses: np.ndarray, records: np.ndarray, seconds: np.ndarray) -> np.ndarray:
    """IMU-to-world ``poses`` [N, 4, 4] moved on by ``seconds`` [N] (negative: back) at their
    records' own velocity and angular rate (in the IMU's axes), as constant over so short a time:
    the IMU where it was when a frame's image was taken rather than when its fix was."""
    records = np.asarray(records, dtype=np.float64)
    out = np.array(poses, dtype=np.float64, copy=True)
    for i, dt in enumerate(np.asarray(seconds, dtype=np.float64)):
        R = out[i, :3, :3].copy()
        out[i, :3, 3] += R @ records[i, VELOCITY] * dt
        out[i, :3, :3] = R @ rotation_vector_matrix(records[i, ANGULAR_RATE] * dt)
    return out

