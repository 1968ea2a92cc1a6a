"""KITTI-360's 3D boxes (``data_3d_bboxes/train/<sequence>.xml``) -> tracks of recorded vehicles.

The file is an OpenCV storage: one element per box (``object1``, ``object2``, ...) holding
``semanticId`` (KITTI-360's own class id, its ``labels.py`` ``kittiId``: 13 car, 14 truck, 34 bus,
...), ``instanceId``, ``timestamp`` (the frame of a moving object's box; -1 for a static one),
``start_frame``/``end_frame`` (the annotated window that holds it), and two OpenCV matrices:
``vertices`` (the box's 8 corners in its own frame) and ``transform`` (4x4), which places them in
the sequence's world: ``corner = A v + t`` (the official ``annotation.py``). ``A`` is a rotation
times the box's size: its columns' lengths are the length, width and height, and the box's x axis
(length, heading, the one the official viewer draws forward), y (width) and z (height, up) are the
3DRealCar axes. The centre is the corners' centre ``A c + t`` (``c`` the middle of ``vertices``,
0 in every published file); each size is a column length times the corners' extent along that
axis (1: corners at +-0.5). A transform whose rotation part is a reflection (det -1) is the same
cuboid with its y axis flipped; that flip keeps the heading.

Boxes of one object (same ``semanticId`` and ``instanceId``) are one track: a moving object's box
holds at its ``timestamp``, a static one in every frame of its window. Where two boxes of one
object claim a frame, the later in the file holds, as the official loader keeps the last. Boxes
of other classes are counted by class, not read further; a vehicle box lacking a field, or whose
transform is not a rotation times positive sizes, is an :class:`InputError` naming the file and
the element (``object12.transform``).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..scene.manifest import COORD_MAX, WLH_MAX
from . import xml_text
from .calib_text import finite_numbers
from .tracks import Box, Track, Tracks

BOXES_BYTES_MAX = 1 << 30  # a sequence's file is tens of MB
# KITTI-360's semanticId (labels.py kittiId) -> class name, for the vehicle classes.
VEHICLES = {13: "car", 14: "truck", 15: "trailer", 16: "caravan", 17: "motorcycle", 18: "bicycle", 33: "train",
            34: "bus", 36: "unknown vehicle"}
DEFAULT_TYPES = ("car", "truck", "bus", "caravan", "trailer")
ROTATION_TOL = 1e-4  # |R^T R - I| of the transform's rotation part, its columns normalised


@dataclass
class Kitti360Box:
    kind: str  # the class name (VEHICLES)
    key: tuple[int, int]  # (semanticId, instanceId): the object
    frames: tuple[int, int]  # sequence frames it holds in, inclusive: (timestamp, timestamp) or the window
    centre: np.ndarray  # [3] world
    rotation: np.ndarray  # [3, 3] 3DRealCar axes in the world
    lwh: np.ndarray  # [3] length, width, height, metres
    where: str  # its element, for messages


def _int(node: ET.Element, tag: str, path: Path, where: str, minimum: int) -> int:
    text = xml_text.text(node, tag, path, where)
    try:
        value = int(text)
    except ValueError:
        raise InputError(path, f"expected an integer, got {text!r}", f"{where}.{tag}") from None
    if value < minimum:
        raise InputError(path, f"expected an integer >= {minimum}, got {value}", f"{where}.{tag}")
    return value


def _matrix(node: ET.Element, tag: str, shape: tuple[int, int], path: Path, where: str) -> np.ndarray:
    """An OpenCV matrix element (``rows``, ``cols``, ``data``) of the given shape."""
    m = node.find(tag)
    if m is None:
        raise InputError(path, "missing", f"{where}.{tag}")
    at = f"{where}.{tag}"
    rows, cols = _int(m, "rows", path, at, 0), _int(m, "cols", path, at, 0)
    if (rows, cols) != shape:
        raise InputError(path, f"expected a {shape[0]}x{shape[1]} matrix, got {rows}x{cols}", f"{at}.rows")
    return finite_numbers(xml_text.text(m, "data", path, at), rows * cols, path, f"{at}.data").reshape(shape)


def _box(node: ET.Element, kind: str, semantic: int, path: Path, where: str) -> Kitti360Box:
    instance = _int(node, "instanceId", path, where, 0)
    timestamp = _int(node, "timestamp", path, where, -1)
    M = _matrix(node, "transform", (4, 4), path, where)
    corners = _matrix(node, "vertices", (8, 3), path, where)
    if not np.allclose(M[3], [0, 0, 0, 1]):
        raise InputError(path, f"last row must be 0 0 0 1, got {M[3].tolist()}", f"{where}.transform")
    A, t = M[:3, :3], M[:3, 3]
    scale = np.linalg.norm(A, axis=0)
    lo, hi = corners.min(0), corners.max(0)
    lwh = scale * (hi - lo)
    if not np.all((lwh > 0) & (lwh <= WLH_MAX)):
        raise InputError(path, f"box sizes {lwh.tolist()} m: expected each in (0, {WLH_MAX:g}]", f"{where}.transform")
    R = A / scale
    if np.abs(R.T @ R - np.eye(3)).max() > ROTATION_TOL:
        raise InputError(path, "not a rotation times the box's sizes (its columns are not orthogonal)",
                         f"{where}.transform")
    if np.linalg.det(R) < 0:
        R = R * [1.0, -1.0, 1.0]
    centre = A @ ((lo + hi) / 2) + t
    if np.abs(centre).max() > COORD_MAX:
        raise InputError(path, f"beyond {COORD_MAX:g} m", f"{where}.transform")
    if timestamp >= 0:
        frames = (timestamp, timestamp)
    else:
        frames = (_int(node, "start_frame", path, where, 0), _int(node, "end_frame", path, where, 0))
        if frames[1] < frames[0]:
            raise InputError(path, f"the window ends ({frames[1]}) before it starts ({frames[0]})",
                             f"{where}.end_frame")
    return Kitti360Box(kind, (semantic, instance), frames, centre, R, lwh, where)


def read_boxes(path: Path, types: tuple[str, ...] = DEFAULT_TYPES) -> tuple[list[Kitti360Box], dict[str, int]]:
    """(the boxes of the classes ``types``, in file order; the other boxes counted by class)."""
    path = Path(path)
    root = xml_text.parse(path, "boxes", BOXES_BYTES_MAX, "a KITTI-360 box file")
    boxes, skipped = [], {}
    for node in root:
        if node.find("semanticId") is None:
            continue  # not a box
        where = node.tag
        semantic = _int(node, "semanticId", path, where, -1)
        kind = VEHICLES.get(semantic)
        if kind is None or kind not in types:
            label = kind or (node.findtext("label") or "").strip() or f"semanticId {semantic}"
            skipped[label] = skipped.get(label, 0) + 1
            continue
        boxes.append(_box(node, kind, semantic, path, where))
    return boxes, skipped


def box_tracks(boxes: list[Kitti360Box], path: Path, frames: dict[int, int],
               skipped: dict[str, int]) -> tuple[Tracks, int]:
    """(the boxes as tracks in the sequence's world, the package's ``source`` frame; the boxes
    that hold in none of the package's frames). ``frames`` maps a sequence frame number to a
    package frame. A track is ``<class>_<instanceId>``; its size is its boxes' median."""
    objects: dict[tuple[int, int], list[Kitti360Box]] = {}
    for b in boxes:
        objects.setdefault(b.key, []).append(b)
    numbers = np.array(sorted(frames), dtype=np.int64)
    tracks, outside = [], 0
    for (_, instance), mine in objects.items():
        by_frame: dict[int, Box] = {}
        for b in mine:
            held = numbers[np.searchsorted(numbers, b.frames[0]):np.searchsorted(numbers, b.frames[1], "right")]
            outside += not len(held)
            for fi in (frames[int(n)] for n in held):
                by_frame[fi] = Box(fi, b.centre, b.rotation, b.where)
        if by_frame:
            length, width, height = np.median(np.stack([b.lwh for b in mine]), axis=0)
            name = f"{mine[0].kind.replace(' ', '_')}_{instance}"
            first = mine[0].where
            tracks.append(Track(name, np.array([width, length, height]), [by_frame[fi] for fi in sorted(by_frame)],
                                first, (f"{first}.transform",) * 3))
    return Tracks(Path(path), "source", tracks, dict(skipped)), outside
