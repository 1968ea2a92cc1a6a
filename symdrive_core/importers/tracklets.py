"""KITTI raw's ``tracklet_labels.xml`` -> tracks of recorded vehicles (for ``existing`` actors).

The file is a boost serialization archive: ``tracklets`` holds one ``item`` per tracked object
(``objectType``, its size ``h w l`` in metres, ``first_frame``) whose ``poses`` hold one ``item``
per frame from ``first_frame`` on (``tx ty tz rx ry rz`` and occlusion and truncation flags). A
pose is the box in the Velodyne's frame at that frame: ``t`` is the centre of the box's *bottom*
face, and the box's axes (x along the length, y to its left, z up: the 3DRealCar axes) are turned
by ``Rz(rz) Ry(ry) Rx(rx)`` (the devkit draws ``rz`` alone; ``rx`` and ``ry`` are 0 in every
published drive). Tracklets carry no id: tracklet ``i`` of the file becomes actor
``tracklet_<i>``. Any malformed part is an :class:`InputError` naming the file and the element
(``tracklets.item[3].poses``).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..scene.manifest import WLH_MAX
from . import xml_text
from .oxts import euler_rotation
from .tracks import Box, Track, Tracks

TRACKLETS_BYTES_MAX = 256 * 1024 * 1024
POSE_FIELDS = ("tx", "ty", "tz", "rx", "ry", "rz")


@dataclass
class Tracklet:
    kind: str  # objectType
    wlh: np.ndarray  # [3] metres
    first_frame: int
    poses: np.ndarray  # [n, 6]: tx ty tz rx ry rz, Velodyne frame, one per frame from first_frame on
    where: str  # its element, for messages


def _number(node: ET.Element, tag: str, path: Path, where: str) -> float:
    text = xml_text.text(node, tag, path, where)
    try:
        value = float(text)
    except ValueError:
        raise InputError(path, f"expected a number, got {text!r}", f"{where}.{tag}") from None
    if not np.isfinite(value):
        raise InputError(path, f"expected a finite number, got {text}", f"{where}.{tag}")
    return value


def _items(node: ET.Element, path: Path, where: str) -> list[ET.Element]:
    """The ``item`` children of a serialized list, checked against its ``count``."""
    items = node.findall("item")
    count = _number(node, "count", path, where)
    if count != len(items):
        raise InputError(path, f"count says {count:g} items, the list holds {len(items)}", f"{where}.count")
    return items


def _tracklet(node: ET.Element, path: Path, where: str) -> Tracklet:
    kind = xml_text.text(node, "objectType", path, where)
    wlh = np.array([_number(node, k, path, where) for k in "wlh"])
    for k, v in zip("wlh", wlh):
        if not 0.0 < v <= WLH_MAX:
            raise InputError(path, f"expected a size in (0, {WLH_MAX:g}] metres, got {v:g}", f"{where}.{k}")
    first = _number(node, "first_frame", path, where)
    if first < 0 or first != int(first):
        raise InputError(path, f"expected a frame number (an integer >= 0), got {first:g}", f"{where}.first_frame")
    poses_node = node.find("poses")
    if poses_node is None:
        raise InputError(path, "missing", f"{where}.poses")
    items = _items(poses_node, path, f"{where}.poses")
    if not items:
        raise InputError(path, "no poses: a tracklet is a box in at least one frame", f"{where}.poses")
    poses = np.array([[_number(item, k, path, f"{where}.poses.item[{j}]") for k in POSE_FIELDS]
                      for j, item in enumerate(items)])
    return Tracklet(kind, wlh, int(first), poses, where)


def read_tracklets(path: Path) -> list[Tracklet]:
    """Every tracklet of a ``tracklet_labels.xml``, in file order."""
    path = Path(path)
    root = xml_text.parse(path, "tracklets", TRACKLETS_BYTES_MAX, "a tracklet file")
    node = root if root.tag == "tracklets" else root.find("tracklets")
    if node is None:
        raise InputError(path, "no tracklets element", "tracklets")
    return [_tracklet(item, path, f"tracklets.item[{i}]") for i, item in enumerate(_items(node, path, "tracklets"))]


def tracklet_tracks(tracklets: list[Tracklet], path: Path, velo_to_camera: np.ndarray, frames: dict[int, int],
                    types: tuple[str, ...]) -> tuple[Tracks, int]:
    """(the tracklets of kinds ``types`` as tracks in the camera frame, the boxes left out because
    their frame is not one of the package's). ``velo_to_camera`` [4, 4] maps the Velodyne's
    frame into the package camera's; ``frames`` maps a drive frame number to a package frame."""
    tracks, skipped, outside = [], {}, 0
    R_cv, t_cv = velo_to_camera[:3, :3], velo_to_camera[:3, 3]
    for i, tl in enumerate(tracklets):
        if tl.kind not in types:
            skipped[tl.kind] = skipped.get(tl.kind, 0) + 1
            continue
        boxes = []
        for j, (tx, ty, tz, rx, ry, rz) in enumerate(tl.poses):
            fi = frames.get(tl.first_frame + j)
            if fi is None:
                outside += 1
                continue
            R = euler_rotation(rx, ry, rz)
            centre = np.array([tx, ty, tz]) + R @ np.array([0.0, 0.0, tl.wlh[2] / 2.0])
            boxes.append(Box(fi, R_cv @ centre + t_cv, R_cv @ R, f"{tl.where}.poses.item[{j}]"))
        if boxes:
            tracks.append(Track(f"tracklet_{i}", tl.wlh, boxes, tl.where, tuple(f"{tl.where}.{k}" for k in "wlh")))
    return Tracks(Path(path), "camera", tracks, skipped), outside
