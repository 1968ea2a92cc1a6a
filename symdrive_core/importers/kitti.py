"""A KITTI odometry sequence (or an excerpt of one) -> :class:`~.package.Source` of one camera or
a stereo rig.

The sequence folder holds one folder per rectified camera (``image_2``/``image_3`` colour,
``image_0``/``image_1`` grey, or ``image_l``/``image_r`` as visual-odometry tutorials copy them;
the first pair found in that order is read, else the one camera folder found first in that order:
most published excerpts hold ``image_2`` alone), ``calib.txt`` with the rectified projection
matrices (``P0: ...`` lines, or unlabelled lines in the order P0, P1, ...) and optionally
``times.txt``.
The poses file has one line per frame: camera 0's camera-to-world 3x4 in metres, in camera 0's
frame at the first frame (OpenCV axes). Images are named by frame number (``000123.png``), so an
excerpt is read with the sequence's full poses file.

Rectified cameras share camera 0's rotation: camera i projects with ``P_i = K_i [I | t_i]`` and
sits at ``-t_i`` in camera 0's frame (``t_i = K_i^-1 P_i[:, 3]``; KITTI's P1 has
``t_x = -0.54 m``: the right camera is 0.54 m to the right). KITTI puts pixel centres at
integer coordinates; the package's K puts them at +0.5. The source notes which KITTI camera the
package holds (``kitti_camera``), so its LiDAR is composed to that camera (:mod:`.kitti_calib`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from .calib_text import check_increasing, finite_numbers, labelled_lines
from .frames import DEFAULT_CAMERA, DEFAULT_FPS, View, group_views
from .kitti_calib import camera_offset, package_intrinsics, projection
from .package import Source
from .stereo import RigTolerance, check_pair

PAIRS = (("image_2", "image_3"), ("image_0", "image_1"), ("image_l", "image_r"))
SINGLES = tuple(folder for pair in zip(*PAIRS) for folder in pair)  # left cameras first
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


def _read_lines(path: Path, what: str) -> list[str]:
    try:
        return [line for line in path.read_text(encoding="utf-8-sig").splitlines() if line.strip()]
    except FileNotFoundError:
        raise InputError(path, "file not found", what) from None
    except (UnicodeDecodeError, IsADirectoryError) as exc:
        raise InputError(path, f"not a text file: {exc}", what) from None


def read_calib(path: Path) -> dict[str, str]:
    """The text of each projection matrix by name (``P0``, ``P1``, ...); each is checked to be
    ``K [I | t]`` where it is used, since converted files fill the cameras they lack with zeros."""
    out = {}
    for i, (label, rest) in enumerate(labelled_lines(_read_lines(path, "calib.txt"))):
        label = f"P{i}" if label is None else label
        if len(label) == 2 and label[0] == "P" and label[1].isdigit():
            out[label] = rest  # Tr, R_rect and the like are not cameras
    return out


def read_poses(path: Path) -> list[np.ndarray]:
    """Camera 0's camera-to-world matrices (4x4), one per line."""
    out = []
    for i, line in enumerate(_read_lines(path, "poses")):
        c2w = np.eye(4)
        c2w[:3] = finite_numbers(line, 12, path, f"line {i + 1}").reshape(3, 4)
        out.append(c2w)
    if not out:
        raise InputError(path, "empty: no poses", "poses")
    return out


def find_cameras(sequence: Path) -> tuple[str, ...]:
    """The image folders to read: the first stereo pair found, else the first single camera."""
    for pair in PAIRS:
        if all((sequence / p).is_dir() for p in pair):
            return pair
    for folder in SINGLES:
        if (sequence / folder).is_dir():
            return (folder,)
    raise InputError(sequence, "no image folder (" + ", ".join(SINGLES) + ")", "SEQUENCE_DIR")


def _projection_name(folder: str) -> str:
    return {"image_l": "P0", "image_r": "P1"}.get(folder, "P" + folder[-1])


def _frames(folder: Path) -> dict[int, Path]:
    """Frame number -> image, for the images named by number."""
    out = {}
    for p in folder.iterdir():
        if p.suffix.lower() in IMAGE_SUFFIXES and p.stem.isdecimal():
            out[int(p.stem)] = p
    if not out:
        raise InputError(folder, "no images named by frame number (000000.png, ...)", "images")
    return out


def _times(path: Path) -> list[float] | None:
    """Seconds of frame n at line n + 1 of ``times.txt`` (None without one); each after the one before."""
    if not path.is_file():
        return None
    times = [float(finite_numbers(line, 1, path, f"line {i + 1}")[0]) for i, line in enumerate(_read_lines(path, "times"))]
    check_increasing(times, list(range(len(times))), path)
    return times


def read_kitti(sequence: str | Path, poses: str | Path | None = None, *, splats: str | Path | None = None,
               camera_name: str = DEFAULT_CAMERA, fps: float = DEFAULT_FPS) -> tuple[Source, str | None]:
    """(the sequence as a source, the right camera's name or None): the left (or only) camera is
    ``camera_name``, a stereo pair's right one ``{camera_name}_right``; a splat PLY (``splats``) is
    taken to be in the poses' frame."""
    from ..io.images import image_size

    sequence = Path(sequence)
    if not sequence.is_dir():
        raise InputError(sequence, "not a folder (expected a KITTI odometry sequence)", "SEQUENCE_DIR")
    folders = find_cameras(sequence)
    calib_path = sequence / "calib.txt"
    calib = read_calib(calib_path)
    poses_path = Path(poses) if poses is not None else sequence / "poses.txt"
    if poses is None and not poses_path.is_file():
        raise InputError(poses_path, "file not found; pass the sequence's poses file with --poses", "--poses")
    c2w0 = read_poses(poses_path)
    times = _times(sequence / "times.txt")
    right = f"{camera_name}_right" if len(folders) == 2 else None
    rig = []  # per camera: (name, projection label, K, offset from camera 0, images, width, height)
    for folder, cam in zip(folders, (camera_name, right)):
        label = _projection_name(folder)
        if label not in calib:
            raise InputError(calib_path, f"no projection matrix for {folder}", label)
        P = projection(calib[label], calib_path, label)
        offset = np.eye(4)
        offset[:3, 3] = camera_offset(P)
        frames = _frames(sequence / folder)
        first = frames[min(frames)]
        width, height, _ = image_size(first, folder)
        rig.append((cam, label, package_intrinsics(P), offset, frames, width, height))
    if right is not None:
        _check_rig(rig, folders, calib_path)
    views = []
    for (cam, label, K, offset, frames, width, height), folder in zip(rig, folders):
        for n, image in sorted(frames.items()):
            if n >= len(c2w0):
                raise InputError(poses_path, f"no pose for frame {n} ({folder}/{image.name}); the file has "
                                 f"{len(c2w0)} lines", f"line {n + 1}")
            if times is not None and n >= len(times):
                raise InputError(sequence / "times.txt", f"no time for frame {n}; the file has {len(times)} lines",
                                 f"line {n + 1}")
            views.append(View(name=f"{cam}/{image.stem}", K=K, width=width, height=height, c2w=c2w0[n] @ offset,
                              source=poses_path, where=f"line {n + 1} ({folder}/{image.name})", image=image,
                              timestamp=None if times is None else times[n]))
    grouped = group_views(views, camera_name=camera_name, fps=fps)
    g = None
    if splats is not None:
        from ..io.ply import read_splats

        g = read_splats(splats)
    # Which KITTI camera the package holds: every KITTI Velodyne transform is composed to it.
    notes = {"poses_file": str(poses_path), "kitti_camera": int(rig[0][1][1:])}
    notes.update({"stereo_pair": list(folders)} if right is not None else {"image_folder": folders[0]})
    return Source("kitti", sequence, grouped, splats=g, splats_path=None if splats is None else Path(splats),
                  notes=notes), right


def _check_rig(rig: list[tuple], pair: tuple[str, str], calib_path: Path) -> None:
    """The pair's images share one size and its projections make a rectified rig."""
    (_, _, _, _, _, w0, h0), (_, _, _, _, frames1, w1, h1) = rig
    if (w1, h1) != (w0, h0):
        image = frames1[min(frames1)]
        raise InputError(image, f"image is {w1}x{h1}, the {pair[0]} images are {w0}x{h0}: not a rectified pair",
                         pair[1])
    check_pair(*(View(name=label, K=K, width=w, height=h, c2w=offset, source=calib_path, where=label)
                 for _, label, K, offset, _, w, h in rig), RigTolerance())
