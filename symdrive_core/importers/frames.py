"""Recorded views -> package cameras on shared frames (rigs), in time order.

Each importer turns its source into :class:`View` records (one per image, OpenCV camera-to-world
in the source frame). :func:`group_views` groups them into package cameras and frames:

* the camera of a view is the first folder of its image name when the images are laid out as
  ``{camera}/{frame}.ext`` (two or more such folders), else the source's camera id when it has
  several, else one camera;
* a frame is an instant the rig recorded: the rest of the image name in the folder layout, the
  n-th image by name of each camera otherwise;
* frames are ordered by timestamp when every view has one, else by image name (numbers inside
  names compare as numbers, so ``img10`` follows ``img9``), and then timed by their numbers at
  ``fps`` (frames 0, 1, 3 at 10 fps: 0, 0.1, 0.3 s, so a gap stays a gap);
* a frame not every camera recorded is left out, and its images listed (``Grouped.left_out``)
  for the import to say so.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

import numpy as np

from ..errors import InputError
from ..scene.paths import check_name, escapes, is_absolute_text

DEFAULT_CAMERA = "front"  # the package camera's name when the source has one camera
DEFAULT_FPS = 10.0  # frame rate for timestamps when the source has none


@dataclass
class View:
    name: str  # image name as the source writes it (relative path, '/' separated)
    K: np.ndarray  # [3, 3]
    width: int
    height: int
    c2w: np.ndarray  # [4, 4] OpenCV camera-to-world, source frame
    source: Path  # the file the view was read from (for messages)
    where: str  # the field in that file (for messages)
    image: Path | None = None  # the recorded image on disk
    camera_id: str = "0"  # the source's camera id
    timestamp: float | None = None
    lens: tuple[str, list[float]] | None = None  # COLMAP camera model and parameters of a distorted view


@dataclass
class Grouped:
    cameras: list[str]
    frame_keys: list[str]
    table: list[list[View]]  # [camera][frame]
    timestamps: list[float]
    left_out: list[View] = field(default_factory=list)  # images of frames not every camera recorded


def named_file(root: Path, name: str, path: Path, where: str) -> Path:
    """``root / name`` for a file a record names (an image, a point cloud), relative to ``root``: a
    record is data, so a name that is absolute or climbs out of ``root`` with ``..`` is refused
    (an :class:`InputError` naming ``path`` and ``where``), never followed."""
    if is_absolute_text(name) or escapes(name):
        raise InputError(path, f"{name!r} lies outside {root}; names in the file are relative to it", where)
    return Path(root) / name


def in_order(grouped: Grouped, cameras) -> Grouped:
    """``grouped`` with its cameras in the order chosen (``group_views`` sorts them by name): the
    first named is the package's first camera, as a dataset importer's ``--cameras`` promises."""
    order = [grouped.cameras.index(c) for c in cameras]
    grouped.cameras = [grouped.cameras[i] for i in order]
    grouped.table = [grouped.table[i] for i in order]
    return grouped


def natural_key(text: str):
    return [(0, int(t), "") if t.isdecimal() else (1, 0, t) for t in re.split(r"(\d+)", text) if t]


def frame_times(keys: list[str], fps: float) -> list[float]:
    """Seconds of frames ``keys`` (in time order) without recorded times: each key's last number
    over ``fps`` from the first's, when those numbers increase along the keys, else one frame
    period apart."""
    numbers = [re.findall(r"\d+", k) for k in keys]
    if all(numbers):
        n = [int(x[-1]) for x in numbers]
        if all(b > a for a, b in zip(n, n[1:])):
            return [(i - n[0]) / fps for i in n]
    return [i / fps for i in range(len(keys))]


def check_views(views: list[View]) -> None:
    """Duplicate image names, non-finite or non-rigid poses, bad intrinsics: InputError naming
    the file and the field."""
    if not views:
        raise InputError("(input)", "no registered images", "images")
    seen: dict[str, View] = {}
    for v in views:
        if v.name in seen:
            raise InputError(v.source, f"duplicate image name {v.name!r} (also at {seen[v.name].where})", v.where)
        seen[v.name] = v
        if not np.all(np.isfinite(v.c2w)):
            raise InputError(v.source, "pose is not finite (NaN or Inf)", v.where)
        R = v.c2w[:3, :3]
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or abs(np.linalg.det(R) - 1) > 1e-4:
            raise InputError(v.source, "pose rotation is not a rotation (orthonormal, det +1)", v.where)
        if not np.all(np.isfinite(v.K)) or v.K[0, 0] <= 0 or v.K[1, 1] <= 0:
            raise InputError(v.source, f"intrinsics are not usable: fx={v.K[0, 0]}, fy={v.K[1, 1]}", v.where)
        if v.width < 1 or v.height < 1:
            raise InputError(v.source, f"image size {v.width}x{v.height}", v.where)
        if v.timestamp is not None and not np.isfinite(v.timestamp):
            raise InputError(v.source, f"timestamp {v.timestamp} is not finite", v.where)


def _folder_layout(views: list[View]) -> bool:
    parts = [PurePosixPath(v.name).parts for v in views]
    return all(len(p) >= 2 for p in parts) and len({p[0] for p in parts}) >= 2


def group_views(views: list[View], *, camera_name: str = DEFAULT_CAMERA, fps: float = DEFAULT_FPS) -> Grouped:
    check_views(views)
    by_cam: dict[str, dict[str, View]] = {}
    if _folder_layout(views):
        for v in views:
            p = PurePosixPath(v.name)
            cam, key = p.parts[0], str(PurePosixPath(*p.parts[1:]).with_suffix(""))
            by_cam.setdefault(cam, {})[key] = v
    else:
        ids = sorted({v.camera_id for v in views}, key=natural_key)
        for cid in ids:
            mine = sorted((v for v in views if v.camera_id == cid), key=lambda v: natural_key(v.name))
            cam = camera_name if len(ids) == 1 else f"camera{cid}"
            if len(ids) == 1:
                by_cam[cam] = {v.name: v for v in mine}
            else:
                by_cam[cam] = {f"{i:06d}": v for i, v in enumerate(mine)}
        if len(ids) > 1:
            counts = {c: len(d) for c, d in by_cam.items()}
            if len(set(counts.values())) != 1:
                v = views[0]
                raise InputError(v.source, "cameras have different numbers of images "
                                 f"({', '.join(f'{c}: {n}' for c, n in counts.items())}); lay the images out as "
                                 "{camera}/{frame}.ext so frames can be matched", "camera_id")
    cameras = sorted(by_cam, key=natural_key)
    for cam in cameras:
        v = next(iter(by_cam[cam].values()))
        check_name(cam, v.where, v.source)
    keys = set.intersection(*(set(d) for d in by_cam.values()))
    if not keys:
        v = views[0]
        raise InputError(v.source, f"the cameras {', '.join(cameras)} share no frame", "images")
    for cam in cameras:  # one size per camera
        vs = [by_cam[cam][k] for k in keys]
        for v in vs:
            if (v.width, v.height) != (vs[0].width, vs[0].height):
                raise InputError(v.source, f"image is {v.width}x{v.height}, other images of camera {cam!r} are "
                                 f"{vs[0].width}x{vs[0].height}", v.where)
    have_time = all(v.timestamp is not None for d in by_cam.values() for v in d.values())
    if have_time:
        t = {k: min(by_cam[c][k].timestamp for c in cameras) for k in keys}
        order = sorted(keys, key=lambda k: (t[k], natural_key(k)))
        times = [float(t[k]) for k in order]
        for a, b in zip(order, order[1:]):
            if t[b] <= t[a]:
                v = min((by_cam[c][b] for c in cameras), key=lambda v: v.timestamp)
                raise InputError(v.source, f"frame {b} has the time of frame {a} ({t[a]:.6f} s): two frames cannot "
                                 "share an instant", v.where)
    else:
        order = sorted(keys, key=natural_key)
        times = frame_times(order, fps)
    table = [[by_cam[c][k] for k in order] for c in cameras]
    left_out = sorted((v for c in cameras for k, v in by_cam[c].items() if k not in keys), key=lambda v: natural_key(v.name))
    return Grouped(cameras, order, table, times, left_out)


def split_heldout(n_frames: int, every: int | None) -> tuple[list[int], list[int]]:
    """(train, held-out) frame indices: every ``every``-th frame held out, starting in the middle
    of the first block (``every=5``: 2, 7, 12, ...), as the demo street does."""
    if not every or every < 2:
        return list(range(n_frames)), []
    held = [i for i in range(n_frames) if i % every == every // 2]
    return [i for i in range(n_frames) if i not in set(held)], held
