"""KITTI's calibration files, in each layout KITTI ships them -> its rectified cameras'
projections and the Velodyne's transform into any one of those cameras.

KITTI rectifies every camera to camera 0: camera i projects a point ``x`` of rectified camera 0's
frame with ``P_i = K_i [I | t_i]``, so it sees ``x + t_i`` and sits at ``-t_i`` in camera 0's frame
(``t_i = K_i^-1 P_i[:, 3]``; P1's ``t_x = -0.54 m`` puts the right grey camera 0.54 m to the right).
Every Velodyne transform KITTI writes ends in camera 0, so a scan reaches camera i as
``x_rect0 + t_i``: given to the colour camera 2 unchanged, it lands 6 cm to the side (about 2 px
at half resolution).

The layouts, with the labels KITTI writes:

- odometry ``calib.txt``: ``P0:`` .. ``P3:`` and ``Tr:``, the Velodyne to rectified camera 0 (the
  rectification is in it);
- tracking ``calib/NNNN.txt``: ``P0:`` .. ``P3:``, then ``R_rect`` and ``Tr_velo_cam`` without
  colons: the Velodyne to camera 0 before rectification, and the rectifying rotation;
- object ``calib/NNNNNN.txt``: the same, as ``R0_rect:`` and ``Tr_velo_to_cam:``;
- raw ``calib_velo_to_cam.txt`` (``R:``, ``T:``: the Velodyne to camera 0 before rectification)
  with ``calib_cam_to_cam.txt`` beside it, as the date folder holds them (``R_rect_00:``, the
  projections ``P_rect_00:`` .. ``P_rect_03:``).

A rectifying rotation is 9 numbers (3x3) or 12 (3x4 ``[R | 0]``, as converted files write it);
lines with other labels (``Tr_imu_velo``, ``calib_time``, ``S_00``) are not read.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import conventions
from ..errors import InputError
from .calib_text import finite_numbers, labelled_lines, read_small_text, rigid_transform

REFERENCE_CAMERA = 0  # the camera every KITTI Velodyne transform ends in
CAMERAS = (0, 1, 2, 3)
RAW_CAM_TO_CAM = "calib_cam_to_cam.txt"
# layout -> (the Velodyne-to-camera-0 label, the rectifying rotation's label; None: already rectified)
LAYOUTS = {"odometry": ("Tr", None), "tracking": ("Tr_velo_cam", "R_rect"), "object": ("Tr_velo_to_cam", "R0_rect")}


def projection(text: str, path: Path, label: str) -> np.ndarray:
    """A rectified projection ``K [I | t]`` (3x4) from its 12 numbers, checked."""
    P = finite_numbers(text, 12, path, label).reshape(3, 4)
    K = P[:, :3]
    if not (np.allclose(K[[1, 2, 2], [0, 0, 1]], 0) and np.isclose(K[2, 2], 1) and K[0, 0] > 0 and K[1, 1] > 0
            and abs(K[0, 1]) < 1e-9 * K[0, 0]):
        raise InputError(path, "not a rectified projection K [I | t] (left 3x3 must be an upper-triangular K "
                         "with no skew and K[2,2] = 1)", label)
    return P


def package_intrinsics(P: np.ndarray) -> np.ndarray:
    """The package K [3, 3] of a rectified projection ``P = K [I | t]``: KITTI puts pixel centres at
    integer coordinates, the package at +0.5."""
    return conventions.intrinsics(P[0, 0], P[1, 1], P[0, 2] + 0.5, P[1, 2] + 0.5)


def camera_offset(P: np.ndarray) -> np.ndarray:
    """Where the camera of ``P = K [I | t]`` sits in camera 0's frame: ``-t``."""
    return -np.linalg.solve(P[:, :3], P[:, 3])


def labels_of(text: str) -> dict[str, str]:
    """Label -> the rest of its line, for the labelled lines of a calibration file."""
    return {label: rest for label, rest in labelled_lines(text.splitlines()) if label is not None}


def read_labels(path: Path, field: str = "calibration") -> dict[str, str]:
    """:func:`labels_of` a calibration file (``field`` names it in a message about its size)."""
    return labels_of(read_small_text(path, field))


def labelled_numbers(labels: dict[str, str], key: str, count, path: Path) -> np.ndarray:
    """The ``count`` numbers of line ``key`` of a calibration file's ``labels`` (a missing line named)."""
    if key not in labels:
        raise InputError(path, f"no {key} line", key)
    return finite_numbers(labels[key], count, path, key)


def labelled_rigid(labels: dict[str, str], path: Path, label: str, counts) -> np.ndarray:
    """A 4x4 from a labelled 3x3 rotation (9 numbers) or 3x4 ``[R | t]`` (12), checked rigid."""
    return rigid_transform(labelled_numbers(labels, label, counts, path), path, label)


def raw_rigid(labels: dict[str, str], path: Path) -> np.ndarray:
    """The 4x4 of a KITTI raw calibration file's ``R`` (9 numbers) and ``T`` (3) lines: the layout
    of ``calib_velo_to_cam.txt`` and ``calib_imu_to_velo.txt``."""
    T = labelled_rigid(labels, path, "R", 9)
    T[:3, 3] = labelled_numbers(labels, "T", 3, path)
    return T


def rectified_camera(labels: dict[str, str], path: Path, i: int, camera: str) -> tuple[np.ndarray, int, int]:
    """(the package K [3, 3], width, height) of rectified camera ``i`` from the ``P_rect_0i`` and
    ``S_rect_0i`` lines of KITTI raw's ``calib_cam_to_cam.txt`` or KITTI-360's ``perspective.txt``
    (one layout); ``camera`` names it in a message (``KITTI camera 2``)."""
    key = f"P_rect_{i:02d}"
    if key not in labels:
        raise InputError(path, f"no {key} line ({camera}'s projection)", key)
    P = projection(labels[key], path, key)
    size = labelled_numbers(labels, f"S_rect_{i:02d}", 2, path)
    if not np.all((size >= 1) & (size == np.round(size))):
        raise InputError(path, f"expected an image size in whole pixels, got {size.tolist()}", f"S_rect_{i:02d}")
    return package_intrinsics(P), int(size[0]), int(size[1])


def layout_of(labels: dict[str, str]) -> str | None:
    """Which KITTI layout a calibration file's labels are, or None (no Velodyne transform in it)."""
    for layout, (velo, _) in LAYOUTS.items():
        if velo in labels:
            return layout
    return "raw" if "R" in labels and "T" in labels else None


def velo_to_camera(path: Path, labels: dict[str, str], camera: int) -> tuple[np.ndarray, str]:
    """(the Velodyne -> rectified camera ``camera`` transform [4, 4], a line saying what it
    composed) from the labels of a KITTI calibration file (``layout_of(labels)`` is not None)."""
    if camera not in CAMERAS:
        raise InputError(path, f"KITTI has cameras {', '.join(map(str, CAMERAS))}, not {camera}", "--kitti-camera")
    layout = layout_of(labels)
    if layout == "raw":
        velo_label, rect_label, p_label = "R, T", "R_rect_00", f"P_rect_0{camera}"
        velo = raw_rigid(labels, path)
        rect_path = path.parent / RAW_CAM_TO_CAM
        if not rect_path.exists():
            raise InputError(rect_path, "file not found: R and T end in camera 0 before rectification, and "
                             "its rectification and projections are in this file beside them", rect_label)
        rect_labels = read_labels(rect_path, rect_label)
    else:
        (velo_label, rect_label), p_label = LAYOUTS[layout], f"P{camera}"
        velo = labelled_rigid(labels, path, velo_label, 12)
        rect_path, rect_labels = path, labels
    T = velo if rect_label is None else labelled_rigid(rect_labels, rect_path, rect_label, (9, 12)) @ velo
    if p_label in rect_labels:
        offset = camera_offset(projection(rect_labels[p_label], rect_path, p_label))
    elif camera == REFERENCE_CAMERA:
        offset, p_label = np.zeros(3), None  # camera 0 is the rectified frame itself
    else:
        raise InputError(rect_path, f"no {p_label} line (KITTI camera {camera}'s projection)", p_label)
    T[:3, 3] -= offset
    composed = ", ".join(x for x in (velo_label, rect_label, p_label) if x)
    return T, (f"KITTI {layout} calibration ({composed}): the Velodyne into rectified camera {camera}, "
               f"which sits at {(np.round(offset, 4) + 0.0).tolist()} m from camera 0")
