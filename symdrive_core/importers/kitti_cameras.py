"""A KITTI rig's rectified cameras as KITTI raw and KITTI-360 both ship them -> package views.

Each camera ``i`` is a folder ``image_0i/`` holding its images, ``<sub>/NNNNNNNNNN.png`` named by
frame number (``data/`` in KITTI raw, ``data_rect/`` in KITTI-360), and ``timestamps.txt`` (line
n: frame n's time, to the nanosecond). Every camera chosen must hold the same frames. A camera's
pose at a frame is the rig's pose there (the IMU from OXTS, rectified camera 0 from KITTI-360's
poses) times where the camera sits on the rig, each dataset composing its own calibration for
that; what this module shares is the folders, the times and the views.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import numpy as np

from ..errors import InputError
from .calib_text import check_increasing
from .frames import View


@dataclass
class RectifiedCamera:
    """One rectified camera of the rig: its package K and image size."""

    index: int
    K: np.ndarray  # [3, 3], package pixel centres (+0.5)
    width: int
    height: int


def camera_name(i: int) -> str:
    """A KITTI camera's package name: its folder's (``image_02``)."""
    return f"image_{i:02d}"


def camera_frames(drive: Path, cameras: tuple[int, ...], sub: str) -> dict[int, dict[str, Path]]:
    """Per camera, frame name -> image of ``image_0i/<sub>/``; every camera must hold the same frames."""
    out: dict[int, dict[str, Path]] = {}
    for i in cameras:
        folder = drive / camera_name(i) / sub
        if not folder.is_dir():
            raise InputError(folder, f"no images of KITTI camera {i}", "--cameras")
        out[i] = {p.stem: p for p in folder.iterdir() if p.suffix.lower() == ".png" and p.stem.isdecimal()}
        if not out[i]:
            raise InputError(folder, "no images named by frame number (0000000000.png, ...)", "images")
    first = cameras[0]
    for i in cameras[1:]:
        missing = sorted(set(out[first]) ^ set(out[i]))
        if missing:
            has, lacks = (first, i) if missing[0] in out[first] else (i, first)
            raise InputError(drive / camera_name(lacks) / sub, f"no {missing[0]}.png, which {camera_name(has)} "
                             f"records: every camera chosen ({', '.join(camera_name(c) for c in cameras)}) must "
                             "record each frame", "--cameras")
    return out


def _clock(text: str, path: Path, where: str) -> tuple[int, float]:
    """(whole seconds since 1970, the fraction) of a KITTI time ``YYYY-MM-DD HH:MM:SS.fffffffff``;
    split so nanoseconds survive where a datetime keeps microseconds."""
    whole, _, frac = text.strip().partition(".")
    try:
        t = datetime.strptime(whole, "%Y-%m-%d %H:%M:%S")
        if frac and not frac.isdigit():
            raise ValueError
    except ValueError:
        raise InputError(path, f"expected a time YYYY-MM-DD HH:MM:SS.fffffffff, got {text.strip()!r}", where) from None
    return int((t - datetime(1970, 1, 1)).total_seconds()), float(f"0.{frac or 0}")


def frame_clocks(path: Path, names: list[str]) -> tuple[list[tuple[int, float]], list[str]] | None:
    """(each of ``names``' time as :func:`_clock` splits it, the file's lines) from a sensor's
    ``timestamps.txt`` (line n: frame n), or None when the sensor has none."""
    if not path.is_file():
        return None
    lines = path.read_text(encoding="utf-8-sig", errors="replace").splitlines()
    clocks = []
    for name in names:
        n = int(name)
        if n >= len(lines) or not lines[n].strip():
            raise InputError(path, f"no time for frame {name}; the file has {len(lines)} lines", f"line {n + 1}")
        clocks.append(_clock(lines[n], path, f"line {n + 1}"))
    return clocks, lines


def clock_lag(later: Path, earlier: Path, names: list[str]) -> np.ndarray | None:
    """[N] seconds from each frame's time in ``earlier``'s ``timestamps.txt`` to its time in
    ``later``'s, or None when either sensor has none."""
    a, b = frame_clocks(later, names), frame_clocks(earlier, names)
    if a is None or b is None:
        return None
    return np.array([float(sa - sb) + (fa - fb) for (sa, fa), (sb, fb) in zip(a[0], b[0])])


def _frame_times(path: Path, names: list[str]) -> tuple[list[float], str] | None:
    """(seconds since the first of ``names``, that frame's time as written) from a camera's
    ``timestamps.txt`` (line n: frame n), or None when the camera has none."""
    read = frame_clocks(path, names)
    if read is None:
        return None
    clocks, lines = read
    s0, f0 = clocks[0]
    times = [float(s - s0) + (f - f0) for s, f in clocks]
    check_increasing(times, [int(name) for name in names], path)
    return times, lines[int(names[0])].strip()


def rig_views(drive: Path, sub: str, rig: dict[int, RectifiedCamera], names: list[str],
              images: dict[int, dict[str, Path]], world_from_rig: np.ndarray, rig_from_camera: dict[int, np.ndarray],
              poses: list[tuple[Path, int]]) -> tuple[list[View], str | None]:
    """(one view per camera of ``rig`` and frame of ``names``, the first frame's time as the
    first camera with a ``timestamps.txt`` writes it, or None). A view's pose is
    ``world_from_rig[fi] @ rig_from_camera[i]``; ``poses[fi]`` is the file and line frame ``fi``'s
    pose was read from, for messages. Views are named ``{camera}/{frame}`` for a rig and by the
    frame alone for one camera: the package's frame names are the frame numbers either way (what
    a dataset's boxes are mapped by)."""
    views, time_origin = [], None
    for i, cam in rig.items():
        folder = camera_name(i)
        times = _frame_times(drive / folder / "timestamps.txt", names)
        if times is not None and time_origin is None:
            time_origin = times[1]
        for fi, name in enumerate(names):
            source, line = poses[fi]
            views.append(View(name=f"{folder}/{name}" if len(rig) > 1 else name, K=cam.K, width=cam.width,
                              height=cam.height, c2w=world_from_rig[fi] @ rig_from_camera[i], source=source,
                              where=f"line {line} ({folder}/{sub}/{name}.png)", image=images[i][name],
                              timestamp=None if times is None else times[0][fi]))
    return views, time_origin
