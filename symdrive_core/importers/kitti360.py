"""A KITTI-360 sequence -> :class:`~.package.Source` of its perspective cameras, with its LiDAR and
vehicle boxes (``symdrive import kitti-360 ROOT --sequence 2013_05_28_drive_0000_sync``).

KITTI-360 ships a sequence spread over the dataset's root: rectified images
``data_2d_raw/<seq>/image_0i/data_rect/NNNNNNNNNN.png`` (cameras 00 and 01, the perspective pair;
02 and 03 are fisheyes, not read) with ``image_0i/timestamps.txt``, Velodyne scans
``data_3d_raw/<seq>/velodyne_points/data/*.bin``, poses ``data_poses/<seq>/cam0_to_world.txt``
(frame number and the 4x4 rectified camera 0 to world) and ``poses.txt`` (frame number and the
3x4 system pose, the IMU/GPS, to world), the 3D boxes ``data_3d_bboxes/train/<seq>.xml``
(:mod:`.kitti360_boxes`) and one ``calibration/`` for every sequence: ``perspective.txt``
(``P_rect_0i``, ``R_rect_0i``, ``S_rect_0i``), ``calib_cam_to_pose.txt`` (``image_0i:`` 3x4,
unrectified camera i to the system pose) and ``calib_cam_to_velo.txt`` (3x4, unrectified camera 0
to the Velodyne).

The conventions are the official kitti360Scripts' (``helpers/project.py``, ``helpers/annotation.py``,
``viewer/kitti360Viewer3DRaw.py``, ``devkits/commons/loadCalibration.py``): rectified camera i's
pose is ``pose T_i R_rect_0i^-1`` (``T_i`` its ``calib_cam_to_pose`` line), which for camera 0 is
what ``cam0_to_world.txt`` holds; so camera i is ``cam0_to_world R_rect_00 T_0^-1 T_i
R_rect_0i^-1``, and ``cam0_to_world.txt`` is read when present, else ``poses.txt`` composed with
``T_0 R_rect_00^-1``. The Velodyne reaches rectified camera i as ``R_rect_0i T_i^-1 T_0
(cam_to_velo)^-1`` (camera 0: ``R_rect_00 (cam_to_velo)^-1``). A camera's K is the left 3x3 of its
``P_rect_0i``, as the official projection uses it (the baseline in ``P_rect_01``'s last column is
the rig's, which ``calib_cam_to_pose`` places already); pixel centres are at integer coordinates
there (it rounds), at +0.5 in the package's K.

KITTI-360's poses skip frames (where the vehicle stood still, and some others): a frame is
imported when camera 0 has its image and the poses file a line for it; images without a pose are
left out, counted in the source's notes (``frames_without_pose``) and printed. ``frames`` picks
sequence frame numbers (a window of a long sequence). The LiDAR enters as :mod:`.kitti_raw`
describes (each package camera's sparse depth, the first camera's coloured returns as the
source's points); the scans are used as recorded, without the official viewer's unwrapping of the
vehicle's motion during a sweep. Vehicle boxes become ``existing`` actors through
:func:`.tracks.add_tracks`, in the package's source frame (the sequence's world). Depth and
actors are added inside the package's temporary folder, so a sequence comes in whole or not at
all; every input is read and checked before anything is written.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import conventions
from ..errors import InputError
from ..scene.paths import check_name
from .calib_text import finite_numbers, read_small_text, rigid_transform
from .frames import DEFAULT_FPS, group_views, in_order
from .kitti360_boxes import DEFAULT_TYPES, Kitti360Box, box_tracks, read_boxes
from .kitti_calib import labelled_rigid, read_labels, rectified_camera
from .kitti_cameras import RectifiedCamera, camera_frames, camera_name, rig_views
from .lidar import LidarConfig, list_scans, seen_returns
from .package import Source, check_image

CAMERAS = (0, 1)  # the perspective pair
IMAGES = "data_rect"
PERSPECTIVE = "perspective.txt"
CAM_TO_POSE = "calib_cam_to_pose.txt"
CAM_TO_VELO = "calib_cam_to_velo.txt"
CAM0_TO_WORLD = "cam0_to_world.txt"
POSES = "poses.txt"
SCANS = Path("velodyne_points") / "data"
POSES_BYTES_MAX = 64 << 20  # a sequence's poses are a few MB


@dataclass(frozen=True)
class Kitti360Config:
    # KITTI-360 perspective cameras made package cameras (image_00, image_01); the first is the
    # package's first camera (ground truth, LiDAR points).
    cameras: tuple[int, ...] = CAMERAS
    # Box classes imported as vehicles (kitti360_boxes.VEHICLES).
    types: tuple[str, ...] = DEFAULT_TYPES
    # Sequence frame numbers to import (None: every frame with an image and a pose).
    frames: tuple[int, ...] | None = None
    # LiDAR returns seen by the first camera kept as the source's points (as KittiRawConfig's).
    lidar_points: int = 100_000
    lidar: LidarConfig = field(default_factory=LidarConfig)


@dataclass
class Camera(RectifiedCamera):
    """One rectified perspective camera: its package K, image size and place on the rig."""

    rect0_from_camera: np.ndarray  # [4, 4] the camera in rectified camera 0's frame
    velo_to_camera: np.ndarray | None  # [4, 4]; None without scans


# ---------------------------------------------------------------- calibration


def _camera_to_pose(path: Path, cameras: tuple[int, ...]) -> dict[int, np.ndarray]:
    """Unrectified camera i -> the system pose, from ``calib_cam_to_pose.txt``'s ``image_0i:`` lines."""
    if not path.is_file():
        raise InputError(path, "file not found (the cameras' places on the vehicle: needed for camera 1 and for "
                         f"{POSES} without {CAM0_TO_WORLD})", "calibration")
    labels = read_labels(path)
    return {i: labelled_rigid(labels, path, camera_name(i), 12) for i in cameras}


def _camera0_to_velo(path: Path) -> np.ndarray:
    if not path.is_file():
        raise InputError(path, "file not found (camera 0 to the Velodyne: needed for the scans)", "calibration")
    return rigid_transform(finite_numbers(read_small_text(path, "calibration"), 12, path, "line 1"), path, "line 1")


def read_rig(calibration: Path, cameras: tuple[int, ...], *, poses_only: bool, scans: bool
             ) -> tuple[dict[int, Camera], np.ndarray | None]:
    """(the rig of ``cameras`` from the ``calibration/`` folder, rectified camera 0 -> the system
    pose or None when not needed). ``poses_only``: the sequence has ``poses.txt`` alone;
    ``scans``: the Velodyne is to be composed to each camera."""
    persp_path = calibration / PERSPECTIVE
    persp = read_labels(persp_path)
    rects = {i: labelled_rigid(persp, persp_path, f"R_rect_{i:02d}", 9) for i in sorted({0, *cameras})}
    pose_from_rect0, to_pose = None, None
    if poses_only or cameras != (0,):
        to_pose = _camera_to_pose(calibration / CAM_TO_POSE, tuple(sorted({0, *cameras})))
        pose_from_rect0 = to_pose[0] @ conventions.invert_rigid(rects[0])
    rect0_from_velo = None
    if scans:
        rect0_from_velo = rects[0] @ conventions.invert_rigid(_camera0_to_velo(calibration / CAM_TO_VELO))
    rig = {}
    for i in cameras:
        K, width, height = rectified_camera(persp, persp_path, i, f"KITTI-360 camera {i}")
        rect0_from_cam = np.eye(4) if i == 0 else \
            conventions.invert_rigid(pose_from_rect0) @ to_pose[i] @ conventions.invert_rigid(rects[i])
        velo = None if rect0_from_velo is None else conventions.invert_rigid(rect0_from_cam) @ rect0_from_velo
        rig[i] = Camera(i, K, width, height, rect0_from_cam, velo)
    return rig, pose_from_rect0


# ---------------------------------------------------------------- poses


def read_poses(path: Path, count: int) -> dict[int, tuple[np.ndarray, int]]:
    """Frame number -> (the pose [4, 4], its line number) of ``cam0_to_world.txt`` (``count`` 16)
    or ``poses.txt`` (12): each line a frame number and a row-major 4x4 or 3x4."""
    text = read_small_text(path, "poses", POSES_BYTES_MAX)
    out: dict[int, tuple[np.ndarray, int]] = {}
    for n, line in enumerate(text.splitlines(), start=1):
        words = line.split()
        if not words:
            continue
        where = f"line {n}"
        if not words[0].isdecimal():
            raise InputError(path, f"expected a frame number first, got {words[0]!r}", where)
        frame = int(words[0])
        if frame in out:
            raise InputError(path, f"frame {frame} has a pose already (line {out[frame][1]})", where)
        out[frame] = (rigid_transform(finite_numbers(" ".join(words[1:]), count, path, where), path, where), n)
    if not out:
        raise InputError(path, "no poses", "line 1")
    return out


# ---------------------------------------------------------------- the sequence


@dataclass
class Kitti360Sequence:
    """What was read: the source, and what :meth:`extend` adds to the written package."""

    source: Source
    cameras: dict[str, Camera]  # package camera name -> its calibration
    scans: list[Path] | None  # one per package frame
    boxes: list[Kitti360Box] | None
    boxes_path: Path
    skipped: dict[str, int]  # boxes of other classes
    config: Kitti360Config
    progress: bool = True

    def extend(self, folder: Path) -> dict:
        """Each package camera's sparse depth and the vehicle boxes as actors, in the package
        being written at ``folder``; a summary for the command's report."""
        from ..scene import load_manifest
        from .lidar import write_depth
        from .tracks import add_tracks

        lidar = []
        if self.scans is not None:
            m = load_manifest(folder)
            for cam in m.cameras:
                to_cam = self.cameras[cam.name].velo_to_camera
                lidar.append(write_depth(m, cam, self.scans, [to_cam] * len(self.scans), config=self.config.lidar,
                                         progress=self.progress))
        tracks = None
        if self.boxes is not None:
            m = load_manifest(folder)
            frames = {int(name): fi for fi, name in enumerate(m.source["frame_names"])}
            found, outside = box_tracks(self.boxes, self.boxes_path, frames, self.skipped)
            tracks = {**add_tracks(m, found), "outside": outside}
        return {"lidar": lidar, "tracks": tracks}


def _frame_names(images: dict[str, Path], posed: dict, frames: tuple[int, ...] | None, folder: Path
                 ) -> tuple[list[str], list[str]]:
    """(the frames imported, the images left out for want of a pose), in frame order."""
    names = sorted(images, key=int)
    if frames is not None:
        wanted = set(frames)
        names = [n for n in names if int(n) in wanted]
        if not names:
            raise InputError(folder, "no image among the frames asked for", "--frames")
    return [n for n in names if int(n) in posed], [n for n in names if int(n) not in posed]


def _scans(folder: Path, names: list[str], images: int, camera: str) -> list[Path]:
    """The scan of each frame in ``names`` (named as its image)."""
    found = {p.name.split(".")[0]: p for p in list_scans(folder)}
    missing = [n for n in names if n not in found]
    if missing:
        raise InputError(folder, f"{len(found)} scans for {images} images of {camera}/{IMAGES}, none for frame "
                         f"{missing[0]}: expected one scan per image, named as it", "velodyne_points")
    return [found[n] for n in names]


def read_kitti360(root: str | Path, sequence: str, config: Kitti360Config = Kitti360Config(), *, splats=None,
                  fps: float = DEFAULT_FPS, progress: bool = True) -> Kitti360Sequence:
    """Read and check one sequence of a KITTI-360 root (``config.cameras``, poses, timestamps,
    the Velodyne's scans and the 3D boxes when present). A splat PLY (``splats``) is taken to be
    in the sequence's world frame."""
    root = Path(root)
    if not root.is_dir():
        raise InputError(root, "not a folder (expected KITTI-360's root: calibration/, data_2d_raw/, data_poses/)",
                         "ROOT")
    check_name(sequence, "--sequence")
    cameras = tuple(config.cameras)
    if not cameras or not set(cameras) <= set(CAMERAS):
        raise InputError("--cameras", f"KITTI-360's perspective cameras are {', '.join(map(str, CAMERAS))}, "
                         f"got {', '.join(map(str, cameras)) or 'none'}")
    seq = root / "data_2d_raw" / sequence
    if not seq.is_dir():
        raise InputError(seq, "no such sequence folder (its images: image_00/data_rect/)", "--sequence")
    pose_path = root / "data_poses" / sequence / CAM0_TO_WORLD
    rectified = pose_path.is_file()
    if not rectified:
        pose_path = pose_path.with_name(POSES)
        if not pose_path.is_file():
            raise InputError(pose_path, f"not found, nor {CAM0_TO_WORLD} beside it: the sequence has no poses",
                             "data_poses")
    scans_dir = root / "data_3d_raw" / sequence / SCANS
    rig, pose_from_rect0 = read_rig(root / "calibration", cameras, poses_only=not rectified,
                                    scans=scans_dir.is_dir())
    images = camera_frames(seq, cameras, IMAGES)
    posed = read_poses(pose_path, 16 if rectified else 12)
    first = camera_name(cameras[0])
    names, unposed = _frame_names(images[cameras[0]], posed, config.frames, seq / first / IMAGES)
    if not names:
        raise InputError(pose_path, f"no frame of {first}/{IMAGES} has a pose (frames {int(unposed[0])} to "
                         f"{int(unposed[-1])} have images)", "frame")
    world_from_rect0 = np.stack([posed[int(n)][0] if rectified else posed[int(n)][0] @ pose_from_rect0
                                 for n in names])
    views, time_origin = rig_views(seq, IMAGES, rig, names, images, world_from_rect0,
                                   {i: rig[i].rect0_from_camera for i in cameras},
                                   [(pose_path, posed[int(n)][1]) for n in names])
    grouped = in_order(group_views(views, camera_name=first, fps=fps), [camera_name(i) for i in cameras])
    scans, points, colors, point_frames = None, None, None, None
    if scans_dir.is_dir():
        scans = _scans(scans_dir, names, len(images[cameras[0]]), first)
        cam = rig[cameras[0]]
        world_from_velo = world_from_rect0 @ cam.rect0_from_camera @ cam.velo_to_camera
        for v in views:  # read for their colours before the package checks them
            check_image(v.image, v.width, v.height, v.source, v.where)
        points, colors, point_frames = seen_returns(
            scans, world_from_velo, [cam.velo_to_camera] * len(scans), cam.K, cam.width, cam.height,
            [images[cameras[0]][n] for n in names], config.lidar_points, config.lidar.min_depth_m)
    boxes_path = root / "data_3d_bboxes" / "train" / f"{sequence}.xml"
    boxes, skipped = read_boxes(boxes_path, tuple(config.types)) if boxes_path.is_file() else (None, {})
    g = None
    if splats is not None:
        from ..io.ply import read_splats

        g = read_splats(splats)
    notes = {"sequence": sequence, "poses": pose_path.name, "time_origin": time_origin,
             "frames_without_pose": len(unposed), "frames_without_pose_first": unposed[:5],
             "kitti360_cameras": {camera_name(i): {"rect0_from_camera": rig[i].rect0_from_camera.tolist()}
                                  for i in cameras}}
    src = Source("kitti-360", root, grouped, splats=g, splats_path=None if splats is None else Path(splats),
                 points=points, colors=colors, point_frames=point_frames, notes=notes)
    return Kitti360Sequence(src, {camera_name(i): rig[i] for i in cameras}, scans, boxes, boxes_path, skipped,
                            config, progress)
