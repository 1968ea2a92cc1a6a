"""Numbers in the text files that come with a recorded drive (calibration, poses, timestamps).

One reader for KITTI's calibration files, poses and ``times.txt`` and for a LiDAR's
sensor-to-camera transform, so a malformed line, or a transform that is no rigid motion, is
refused the same way everywhere: naming the file and the entry.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .. import conventions
from ..errors import InputError

_LABEL = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(?::|\s)(.*)$")


def finite_numbers(text: str, count: int | tuple[int, ...], path: Path, where: str) -> np.ndarray:
    """The ``count`` finite numbers of ``text`` (separated by spaces or commas), float64; anything
    else is an :class:`InputError` naming ``path`` and ``where``. A tuple of counts accepts any of
    them (a rotation written as 3x3 or 3x4)."""
    counts = (count,) if isinstance(count, int) else count
    expected = " or ".join(str(c) for c in counts)
    try:
        v = np.array([float(x) for x in text.replace(",", " ").split()], dtype=np.float64)
    except ValueError:
        raise InputError(path, f"expected {expected} numbers", where) from None
    if len(v) not in counts:
        raise InputError(path, f"expected {expected} numbers, got {len(v)}", where)
    if not np.isfinite(v).all():
        i = int(np.flatnonzero(~np.isfinite(v))[0])
        raise InputError(path, f"number {i + 1} is {v[i]}, not a finite number", where)
    return v


def check_increasing(times: list[float], frames: list[int], path: Path) -> None:
    """Each frame's time after the one before it (``frames``: their numbers, frame n at line n + 1
    of ``path``), else an :class:`InputError` naming the line."""
    for fa, a, fb, b in zip(frames, times, frames[1:], times[1:]):
        if b <= a:
            raise InputError(path, f"frame {fb}'s time {b:g} s is not after frame {fa}'s ({a:g} s)", f"line {fb + 1}")


def rigid_transform(values: np.ndarray, path: Path, where: str) -> np.ndarray:
    """A 4x4 from row-major numbers: a 3x3 rotation (9), ``[R | t]`` (12) or a whole 4x4 (16),
    checked rigid (an :class:`InputError` naming ``path`` and ``where`` otherwise)."""
    T = np.eye(4)
    if len(values) == 9:
        T[:3, :3] = values.reshape(3, 3)
    else:
        T[: len(values) // 4] = values.reshape(-1, 4)
    if not conventions.is_rigid(T):
        last_row = "; last row 0 0 0 1" if len(values) == 16 else ""
        raise InputError(path, f"not a rigid transform (rotation must be orthonormal, det +1{last_row})", where)
    return T


def labelled_lines(lines: list[str]) -> list[tuple[str | None, str]]:
    """(label, the rest) of each line: ``label: ...`` or ``label ...`` (KITTI's tracking files
    write ``R_rect`` and ``Tr_velo_cam`` without the colon), and ``(None, line)`` for a line of
    numbers alone."""
    out = []
    for line in lines:
        m = _LABEL.match(line)
        out.append((m.group(1), m.group(2)) if m else (None, line))
    return out


def read_small_text(path: Path, field: str, limit: int = 1 << 20) -> str:
    """The text of a calibration file: a regular file of at most ``limit`` bytes (a larger one is
    no calibration, and is not read whole)."""
    from ..io import check_regular

    if check_regular(path, field).st_size > limit:
        raise InputError(path, f"larger than {limit >> 20} MB: not a calibration file", field)
    return Path(path).read_text(encoding="utf-8-sig", errors="replace")
