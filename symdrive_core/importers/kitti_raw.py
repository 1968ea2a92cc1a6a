"""A KITTI raw drive -> :class:`~.package.Source` of its cameras, with its LiDAR and tracked vehicles.

KITTI ships a drive as ``DATE/DATE_drive_NNNN_sync/`` (rectified images ``image_0i/data/*.png``
with ``image_0i/timestamps.txt``, ``oxts/data/*.txt``, ``velodyne_points/data/*.bin`` and, for
labelled drives, ``tracklet_labels.xml``) and the date's calibration beside it in ``DATE/``:
``calib_cam_to_cam.txt`` (``R_rect_00``, ``P_rect_0i``, ``S_rect_0i``), ``calib_velo_to_cam.txt``
and ``calib_imu_to_velo.txt`` (``R``, ``T``). Frames are named by number in every folder, so an
excerpt of a drive reads the same way.

Every transform is composed to the camera the package holds, as the devkit and pykitti compose
them (:mod:`.kitti_calib`): rectified camera ``i`` from the Velodyne is ``T_i R_rect_00
T_velo_to_cam`` and from the IMU that times ``T_imu_to_velo``, where ``T_i`` moves rectified camera
0's frame to camera ``i``'s (camera ``i`` sits at ``-K_i^-1 P_rect_0i[:, 3]`` in it: the colour
cameras 6 cm left and 0.47 m right of camera 0). A camera's pose at a frame is the IMU's pose from
OXTS (:mod:`.oxts`), carried from the fix's time to the first camera's image time when both
``timestamps.txt`` are there, times the inverse of that chain. KITTI puts pixel centres at integer
coordinates; the package's K puts them at +0.5.

The LiDAR enters two ways, from the same scans: each package camera's sparse depth (the scans
projected by :func:`.lidar.import_lidar`, composed to that camera), and the returns the first
camera sees, coloured from its images, as the source's points: a metric ground to fit under the
camera path, and the points the reconstruction starts from. Tracklets become ``existing`` actors
through the tracks writer (:func:`.tracks.add_tracks`). Depth and actors are added inside the
package's temporary folder (:func:`.package.write_package`'s ``extend``), so a drive comes in whole
or not at all; every input is read and checked before anything is written.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import conventions
from ..errors import InputError
from .frames import DEFAULT_FPS, group_views, in_order
from .kitti_calib import RAW_CAM_TO_CAM, layout_of, raw_rigid, read_labels, rectified_camera, velo_to_camera
from .kitti_cameras import RectifiedCamera, camera_frames, camera_name, clock_lag, rig_views
from .lidar import LidarConfig, list_scans, seen_returns
from .oxts import carried, imu_poses, read_record
from .package import Source, check_image
from .tracklets import Tracklet, read_tracklets
from .tracks import TracksConfig

CALIB_VELO_TO_CAM = "calib_velo_to_cam.txt"
CALIB_IMU_TO_VELO = "calib_imu_to_velo.txt"
TRACKLETS = "tracklet_labels.xml"
SCANS = Path("velodyne_points") / "data"


@dataclass(frozen=True)
class KittiRawConfig:
    # KITTI cameras made package cameras (0, 1 grey; 2, 3 the colour pair); the first is the
    # package's first camera (ground truth, tracked boxes).
    cameras: tuple[int, ...] = (2, 3)
    # Tracklet object types imported as vehicles.
    types: tuple[str, ...] = TracksConfig.types
    # LiDAR returns seen by the first camera kept as the source's points (spread evenly over the
    # scans): enough for the ground fit and the reconstruction's start, which keeps 30k of them.
    lidar_points: int = 100_000
    lidar: LidarConfig = field(default_factory=LidarConfig)


# ---------------------------------------------------------------- calibration


@dataclass
class Camera(RectifiedCamera):
    """One rectified KITTI camera: its package K, image size and where it sits on the rig."""

    velo_to_camera: np.ndarray  # [4, 4]
    imu_to_camera: np.ndarray  # [4, 4]


def read_calibration(date_dir: Path, cameras: tuple[int, ...]) -> dict[int, Camera]:
    """The rig of ``cameras`` from the date folder's three calibration files."""
    rect_path, velo_path = date_dir / RAW_CAM_TO_CAM, date_dir / CALIB_VELO_TO_CAM
    rect, velo = read_labels(rect_path), read_labels(velo_path)
    if layout_of(velo) != "raw":
        raise InputError(velo_path, "no R and T lines (the Velodyne to camera 0 before rectification)", "R")
    imu_path = date_dir / CALIB_IMU_TO_VELO
    imu_to_velo = raw_rigid(read_labels(imu_path), imu_path)
    out = {}
    for i in cameras:
        K, width, height = rectified_camera(rect, rect_path, i, f"KITTI camera {i}")
        velo_to_cam, _ = velo_to_camera(velo_path, velo, i)
        out[i] = Camera(i, K, width, height, velo_to_cam, velo_to_cam @ imu_to_velo)
    return out


# ---------------------------------------------------------------- the drive


@dataclass
class KittiRawDrive:
    """What was read: the source, and what :meth:`extend` adds to the written package."""

    source: Source
    cameras: dict[str, Camera]  # package camera name -> its calibration
    calibration: Path  # calib_velo_to_cam.txt, which LiDAR depth composes to each camera
    scans: Path | None  # the Velodyne folder, one scan per frame in frame order
    tracklets: list[Tracklet] | None
    tracklets_path: Path
    config: KittiRawConfig
    progress: bool = True

    def extend(self, folder: Path) -> dict:
        """Each package camera's sparse depth and the tracklets as actors, in the package being
        written at ``folder``; a summary for the command's report."""
        from ..scene import load_manifest
        from .lidar import import_lidar
        from .tracklets import tracklet_tracks
        from .tracks import add_tracks

        lidar = []
        if self.scans is not None:
            for cam in load_manifest(folder).cameras:
                lidar.append(import_lidar(folder, self.scans, self.calibration, camera=cam.name,
                                          kitti_camera=self.cameras[cam.name].index, config=self.config.lidar,
                                          progress=self.progress))
        tracks = None
        if self.tracklets is not None:
            m = load_manifest(folder)
            first = m.cameras[0].name
            frames = {int(name): fi for fi, name in enumerate(m.source["frame_names"])}
            found, outside = tracklet_tracks(self.tracklets, self.tracklets_path, self.cameras[first].velo_to_camera,
                                             frames, self.config.types)
            tracks = {**add_tracks(m, found, camera=first), "outside": outside}
        return {"lidar": lidar, "tracks": tracks}


def read_kitti_raw(drive: str | Path, config: KittiRawConfig = KittiRawConfig(), *, splats=None,
                   fps: float = DEFAULT_FPS, progress: bool = True) -> KittiRawDrive:
    """Read and check a whole drive (``config.cameras``, OXTS, timestamps, the Velodyne's scans
    when present, ``tracklet_labels.xml`` when present). A splat PLY (``splats``) is taken to be in
    the source frame: East-North-Up metres about the first frame's OXTS position."""
    drive = Path(drive)
    if not drive.is_dir():
        raise InputError(drive, "not a folder (expected a KITTI raw drive, DATE/DATE_drive_NNNN_sync)", "DRIVE_DIR")
    cameras = tuple(config.cameras)
    rig = read_calibration(drive.resolve().parent, cameras)
    images = camera_frames(drive, cameras, "data")
    names = sorted(images[cameras[0]], key=int)
    oxts = [drive / "oxts" / "data" / f"{name}.txt" for name in names]
    records = np.stack([read_record(p) for p in oxts])
    world_from_imu, projection = imu_poses(records)
    lag = clock_lag(drive / camera_name(cameras[0]) / "timestamps.txt", drive / "oxts" / "timestamps.txt", names)
    if lag is not None:  # the rig's cameras are triggered together: the first one's times are the rig's
        world_from_imu = carried(world_from_imu, records, lag)
    views, time_origin = rig_views(drive, "data", rig, names, images, world_from_imu,
                                   {i: conventions.invert_rigid(rig[i].imu_to_camera) for i in cameras},
                                   [(p, 1) for p in oxts])
    grouped = in_order(group_views(views, camera_name=camera_name(cameras[0]), fps=fps),
                       [camera_name(i) for i in cameras])
    first = rig[cameras[0]]
    scans_dir, points, colors, point_frames = drive / SCANS, None, None, None
    if scans_dir.is_dir():
        scans = list_scans(scans_dir)
        if [p.stem for p in scans] != names:
            missing = sorted(set(names) ^ {p.stem for p in scans}, key=int)
            raise InputError(scans_dir, f"{len(scans)} scans for {len(names)} frames of {camera_name(cameras[0])}"
                             f"/data (frame {missing[0] if missing else '?'}): expected one scan per image, named "
                             "as it", "velodyne_points")
        world_from_velo = world_from_imu @ conventions.invert_rigid(first.imu_to_camera) @ first.velo_to_camera
        for v in views:  # read for their colours before the package checks them
            check_image(v.image, v.width, v.height, v.source, v.where)
        points, colors, point_frames = seen_returns(
            scans, world_from_velo, [first.velo_to_camera] * len(scans), first.K, first.width, first.height,
            [images[cameras[0]][n] for n in names], config.lidar_points, config.lidar.min_depth_m)
    tracklets_path = drive / TRACKLETS
    tracklets = read_tracklets(tracklets_path) if tracklets_path.is_file() else None
    g = None
    if splats is not None:
        from ..io.ply import read_splats

        g = read_splats(splats)
    notes = {"drive": drive.name, "oxts": projection, "time_origin": time_origin,
             "oxts_to_image_s": None if lag is None else {"min": float(lag.min()), "max": float(lag.max())},
             "kitti_cameras": {camera_name(i): {"imu_to_camera": rig[i].imu_to_camera.tolist()} for i in cameras}}
    src = Source("kitti-raw", drive, grouped, splats=g, splats_path=None if splats is None else Path(splats),
                 points=points, colors=colors, point_frames=point_frames, notes=notes)
    return KittiRawDrive(src, {camera_name(i): rig[i] for i in cameras}, drive.resolve().parent / CALIB_VELO_TO_CAM,
                         scans_dir if points is not None else None,
                         tracklets, tracklets_path, config, progress)
