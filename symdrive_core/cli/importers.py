"""``symdrive import colmap|nerfstudio|3dgs|kitti``: a reconstruction or a KITTI drive -> a scene package
(``kitti-raw``, ``kitti-360``: with its LiDAR depth and tracked vehicles);
``symdrive import lidar``: its LiDAR scans -> the package's sparse depth; ``symdrive import tracks``:
its vehicles' per-frame boxes -> the package's existing actors."""

from __future__ import annotations

import argparse
import sys
import time
from functools import partial

from ..importers.frames import DEFAULT_CAMERA, DEFAULT_FPS
from ..importers.kitti360 import Kitti360Config
from ..importers.kitti_calib import CAMERAS as KITTI_CAMERAS
from ..importers.kitti_raw import KittiRawConfig
from ..importers.nuscenes import NuScenesConfig
from ..importers.start_points import StartPointsConfig
from ..importers.tracks import TRACK_FORMATS, TracksConfig
from . import (
    add_quiet_option,
    count_int,
    default_of,
    frames_arg,
    names_arg,
    number_at_least_zero,
    positive_int,
    positive_number,
)


def _common(p, images: bool, camera_name: bool = True) -> None:
    if images:
        p.add_argument("--images", help="folder of the recorded images (paths in the model are relative to it)")
    p.add_argument("--out", required=True, help="scene package folder to write (written whole, or not at all)")
    p.add_argument("--splats", help="trained 3DGS splat PLY in the same frame as the cameras")
    p.add_argument("--camera-height", type=positive_number,
                   help="the cameras' height above the ground in metres: sets the metric scale from the fitted "
                        "ground, or with --scale (or without points) places the ground that far below the cameras")
    p.add_argument("--scale", type=positive_number, help="metres per source unit (--scale 1: the poses are metric)")
    p.add_argument("--up", help="the world's up direction x,y,z in the source frame (default: fitted ground "
                                "plane, checked against the cameras' mean up vector)")
    p.add_argument("--heldout-every", type=positive_int, metavar="N",
                   help="hold every N-th frame out of training for evaluation (N=5: frames 2, 7, 12, ...)")
    p.add_argument("--copy-images", action="store_true",
                   help="copy the images into the package (default: reference them, relative to the package)")
    if camera_name:
        p.add_argument("--camera-name", default=DEFAULT_CAMERA,
                       help=f"name of the package camera when there is one ({DEFAULT_CAMERA})")
    p.add_argument("--fps", type=positive_number, default=DEFAULT_FPS,
                   help=f"frame rate for timestamps when the source has none ({DEFAULT_FPS:g})")
    p.add_argument("--name", help="scene name (default: the package folder's name)")
    p.add_argument("--force", action="store_true", help="replace --out if it exists")
    add_quiet_option(p)


def add_commands(sub) -> None:
    imp = sub.add_parser("import", help="turn a COLMAP, nerfstudio or 3DGS reconstruction, or a KITTI sequence, into "
                                        "a scene package; add LiDAR depth or tracked vehicles to one")
    isub = imp.add_subparsers(dest="format", required=True, metavar="FORMAT")
    p = isub.add_parser("colmap", help="COLMAP sparse model (text or binary); distorted cameras with --undistort")
    p.add_argument("model", metavar="MODEL_DIR", help="folder with cameras/images/points3D .bin or .txt")
    _common(p, images=True)
    p.add_argument("--undistort", action="store_true",
                   help="undistort cameras with lens distortion (SIMPLE_RADIAL, OPENCV, ...) with COLMAP's "
                        "undistorter: PINHOLE cameras, resampled images copied into the package")
    _lateral_truth_option(p)
    p.set_defaults(func=_colmap)
    p = isub.add_parser("nerfstudio", help="nerfstudio transforms.json (OpenGL camera axes)")
    p.add_argument("transforms", metavar="TRANSFORMS_JSON", help="nerfstudio transforms.json")
    _common(p, images=False)
    _lateral_truth_option(p)
    p.add_argument("--undistort", action="store_true",
                   help="undistort cameras with lens distortion (OPENCV, OPENCV_FISHEYE) with COLMAP's undistorter: "
                        "PINHOLE cameras, resampled images copied into the package")
    p.set_defaults(func=_nerfstudio)
    p = isub.add_parser("kitti", help="KITTI odometry sequence (one camera or a rectified stereo pair, calib.txt, "
                                      "poses): the left camera, a pair's right one as lateral ground truth")
    p.add_argument("sequence", metavar="SEQUENCE_DIR",
                   help="folder with image_2/image_3 (or image_0/image_1, image_l/image_r), or one of them alone, "
                        "and calib.txt")
    p.add_argument("--poses", help="the sequence's poses file, metres (default: SEQUENCE_DIR/poses.txt)")
    p.add_argument("--rig", action="store_true",
                   help="a stereo pair's cameras both trained on (the package's second camera is the right one); "
                        "default: the right camera's images are lateral ground truth, not trained on")
    _common(p, images=False)
    p.set_defaults(func=_kitti)
    _kitti_raw_command(isub)
    _kitti360_command(isub)
    _nuscenes_command(isub)
    p = isub.add_parser("3dgs", help="the original 3DGS trainer's output folder (cameras.json, point_cloud/)")
    p.add_argument("model", metavar="MODEL_DIR", help="the 3DGS trainer's output folder (cameras.json, point_cloud/)")
    _common(p, images=True)
    p.add_argument("--iteration", type=count_int, help="point_cloud/iteration_N to use (default: the newest)")
    p.set_defaults(func=_gs)
    p = isub.add_parser("lidar", help="add sparse depth from per-frame LiDAR scans to a scene package")
    p.add_argument("package", metavar="PACKAGE", help="scene package folder (or its manifest.json)")
    p.add_argument("scans", metavar="SCANS_DIR",
                   help="one scan per package frame, in name order: KITTI velodyne .bin, .npz with 'points', or .ply")
    p.add_argument("--sensor-to-camera", required=True, metavar="FILE",
                   help="the LiDAR-to-camera rigid transform: 12 or 16 numbers (row-major 3x4 or 4x4), or a KITTI "
                        "calibration file (odometry calib.txt, tracking or object calib, raw calib_velo_to_cam.txt "
                        "with calib_cam_to_cam.txt beside it)")
    p.add_argument("--camera", help="the package camera the scans are projected into (default: the first)")
    p.add_argument("--kitti-camera", type=int, metavar="N",
                   help="the KITTI camera (0-3) the package camera is, for a KITTI calibration file (default: the one "
                        "a KITTI import notes in the package, else 0)")
    p.add_argument("--min-depth", type=number_at_least_zero, metavar="M",
                   help="drop returns nearer to the camera than this, in metres (default: LidarConfig)")
    p.add_argument("--force", action="store_true", help="replace the camera's depth maps if it has some")
    add_quiet_option(p)
    p.set_defaults(func=_lidar)
    _tracks_command(isub)


def _kitti_raw_command(isub) -> None:
    p = isub.add_parser("kitti-raw", help="KITTI raw drive (DATE/DATE_drive_NNNN_sync with the date's calibration "
                                          "beside it): its cameras, OXTS poses, Velodyne depth and tracklets")
    p.add_argument("drive", metavar="DRIVE_DIR",
                   help="the drive's _sync folder (image_0i/, oxts/, velodyne_points/, tracklet_labels.xml), "
                        "its parent holding calib_cam_to_cam.txt, calib_velo_to_cam.txt, calib_imu_to_velo.txt")
    p.add_argument("--cameras", type=_camera_list, metavar="I,...",
                   help="KITTI cameras to import as package cameras image_0I (0, 1 grey; 2, 3 colour; default "
                        f"{','.join(map(str, KittiRawConfig.cameras))})")
    p.add_argument("--types", type=_type_list, metavar="TYPE,...",
                   help=f"tracklet object types imported as vehicles (default {','.join(KittiRawConfig.types)})")
    _common(p, images=False, camera_name=False)
    _lateral_truth_option(p)
    _lidar_start_option(p)
    p.set_defaults(func=_kitti_raw)


def _kitti360_command(isub) -> None:
    p = isub.add_parser("kitti-360", help="KITTI-360 sequence (ROOT with calibration/, data_2d_raw/, data_poses/): its "
                                          "perspective cameras, poses, Velodyne depth and vehicle boxes")
    p.add_argument("root", metavar="ROOT", help="KITTI-360's root folder (calibration/, data_2d_raw/, data_3d_raw/, "
                                                "data_poses/, data_3d_bboxes/)")
    p.add_argument("--sequence", required=True, help="the sequence's folder name (2013_05_28_drive_0000_sync)")
    p.add_argument("--cameras", type=_camera_list, metavar="I,...",
                   help="perspective cameras imported as package cameras image_0I (default "
                        f"{','.join(map(str, Kitti360Config.cameras))})")
    p.add_argument("--frames", type=frames_arg, metavar="A:B,...",
                   help="sequence frame numbers to import, e.g. 250:499 (default: every frame with an image and a pose)")
    p.add_argument("--types", type=_type_list, metavar="CLASS,...",
                   help=f"box classes imported as vehicles (default {','.join(Kitti360Config.types)})")
    _common(p, images=False, camera_name=False)
    _lateral_truth_option(p)
    _lidar_start_option(p)
    p.set_defaults(func=_kitti360)


def _lidar_start_option(p) -> None:
    p.add_argument("--triangulate-beyond-lidar", action=argparse.BooleanOptionalAction, default=None,
                   help="join the LiDAR's returns, where the reconstruction starts, with points triangulated from "
                        f"the training images where no return is within {StartPointsConfig.beyond_lidar_m:g} m "
                        "(default: on; the tops of trees and buildings, the far street)")


def _camera_list(text: str) -> tuple[int, ...]:
    try:
        cameras = tuple(int(t) for t in text.split(","))
    except ValueError:
        cameras = ()
    if not cameras or len(set(cameras)) != len(cameras) or not set(cameras) <= set(KITTI_CAMERAS):
        raise argparse.ArgumentTypeError(f"expected distinct KITTI cameras among "
                                         f"{','.join(map(str, KITTI_CAMERAS))} (2,3), got {text!r}")
    return cameras


def _nuscenes_command(isub) -> None:
    p = isub.add_parser("nuscenes", help="nuScenes scene (DATAROOT with VERSION/ tables and samples/): its cameras, "
                                         "ego poses, LIDAR_TOP depth and annotated vehicles")
    p.add_argument("dataroot", metavar="DATAROOT", help="the folder holding VERSION/ (scene.json, ...) and samples/")
    p.add_argument("--version", help=f"the tables' folder under DATAROOT (default {NuScenesConfig.version})")
    p.add_argument("--scene", required=True, help="the scene's name (scene-0061)")
    p.add_argument("--cameras", type=names_arg, metavar="CAM,...",
                   help="channels imported as package cameras, the first the package's first "
                        f"(default {','.join(NuScenesConfig.cameras)})")
    _common(p, images=False, camera_name=False)
    _lidar_start_option(p)
    p.set_defaults(func=_nuscenes)


def _tracks_command(isub) -> None:
    p = isub.add_parser("tracks", help="add a recorded drive's tracked vehicles (per-frame 3D boxes) to a scene "
                                       "package as existing actors")
    p.add_argument("package", metavar="PACKAGE", help="scene package folder (or its manifest.json)")
    p.add_argument("tracks", metavar="TRACKS_FILE",
                   help="tracks as JSON (.json; format in docs/import.md) or KITTI tracking labels (.txt)")
    p.add_argument("--format", dest="tracks_format", choices=TRACK_FORMATS,
                   help="the file's format (default: from its suffix)")
    p.add_argument("--types", type=_type_list, metavar="TYPE,...",
                   help=f"KITTI object types to keep; DontCare never is (default {','.join(TracksConfig.types)})")
    p.add_argument("--frame-offset", type=int, metavar="N",
                   help="a box's frame minus N is its package frame, for a package that is a window of the "
                        f"sequence (default {default_of(TracksConfig, 'frame_offset')})")
    p.add_argument("--camera", help="the package camera of boxes in camera coordinates (default: the first)")
    p.add_argument("--calib", metavar="FILE",
                   help="KITTI calibration file: its P2 moves KITTI's boxes from rectified camera 0's frame into "
                        "camera 2's (the package camera of a colour KITTI import)")
    p.add_argument("--replace", action="store_true",
                   help="tracks replace actors of kind existing with the same id (kind inserted never)")
    p.set_defaults(func=_tracks)


def _type_list(text: str) -> tuple[str, ...]:
    types = tuple(t.strip() for t in text.split(",") if t.strip())
    if not types:
        raise argparse.ArgumentTypeError(f"expected comma-separated object types (Car,Van), got {text!r}")
    return types


def _lateral_truth_option(p) -> None:
    p.add_argument("--lateral-truth", metavar="CAMERA",
                   help="a rectified rig's second camera: not trained on, its images become lateral ground truth of "
                        "the first camera at the baseline measured from the poses")


def _with_lateral_truth(src, args):
    """``src`` with camera ``--lateral-truth`` taken out of its cameras as lateral ground truth."""
    from ..importers.stereo import split_rig

    if args.lateral_truth is not None:
        src.grouped, src.lateral = split_rig(src.grouped, args.lateral_truth)
    return src


def _options(args, copy_images: bool = False):
    from pathlib import Path

    from ..errors import InputError
    from ..importers.package import Options, parse_up

    if args.heldout_every is not None and args.heldout_every < 2:
        raise InputError("--heldout-every", f"expected N >= 2, got {args.heldout_every}")
    return Options(out=Path(args.out), camera_height=args.camera_height, scale=args.scale, up=parse_up(args.up),
                   heldout_every=args.heldout_every, copy_images=args.copy_images or copy_images, force=args.force, name=args.name)


def _start_points(src, opt, args) -> None:
    """The start points (:mod:`..importers.start_points`); a source with neither points nor images
    can still be placed by --up and --camera-height alone."""
    from dataclasses import replace

    from ..errors import InputError
    from ..importers.start_points import start_points
    from . import given

    fields = given(args, "triangulate_beyond_lidar") if hasattr(args, "triangulate_beyond_lidar") else {}
    start_points(src, opt.out, opt.heldout_every, replace(StartPointsConfig(), **fields),
                 log=lambda line: print(line, flush=True))
    if src.splats is not None or (src.points is not None and len(src.points)):
        return
    placed = opt.up is not None and opt.camera_height is not None
    if src.points is None and not placed:
        raise InputError(src.path, "no points, and no images to triangulate them from: pass --images DIR, or "
                         "--up x,y,z and --camera-height H to place the ground below the cameras", "points")
    if src.points is not None and not placed:
        raise InputError(src.path, "no points triangulated from the images (too little overlap or texture between "
                         "the frames): pass --up x,y,z and --camera-height H to place the ground below the cameras",
                         "points")
    print("warning: the package has no points: 'symdrive reconstruct' has nothing to start from (give the source "
          "splats, a point cloud or LiDAR scans)", file=sys.stderr)


def _finish(src, args, t0, copy_images: bool = False, options=None, extend=None, report=None) -> int:
    from ..importers.package import write_package

    opt = options or _options(args, copy_images)
    if left_out := [v.name for v in src.grouped.left_out]:
        src.notes["images_left_out"] = left_out
        print(f"warning: {len(left_out)} image(s) left out, of frames not every camera recorded: "
              f"{', '.join(left_out[:5])}{', ...' if len(left_out) > 5 else ''}", file=sys.stderr)
    _start_points(src, opt, args)
    info = write_package(src, opt, progress=not args.quiet, extend=extend)
    print(f"{info['package']}: {info['frames']} frames, cameras {', '.join(info['cameras'])}, "
          f"scale {info['scale']:.6g} m per source unit, camera height {info['camera_height_m']:.3f} m "
          f"({time.perf_counter() - t0:.1f} s)")
    if report is not None:
        report(info["extended"])
    if src.lateral is not None:
        print(f"lateral ground truth: camera {src.lateral.name}, {len(src.lateral.views)} images at "
              f"{info['lateral_offset_m']:+g} m of camera {src.lateral.camera} (not trained on)")
    q = info["ground_fit"]
    if q["corridor_points"]:
        print(f"ground: {q['inliers']} of {q['corridor_points']} points under the camera path on the plane "
              f"({q['inlier_fraction']:.0%}), residual RMS {100 * q['residual_rms_m']:.1f} cm, camera height "
              f"spread {100 * q['camera_height_spread_m']:.1f} cm")
    if q["weak"]:
        placed = opt.up is not None and opt.camera_height is not None and opt.scale is not None
        print(f"warning: weak ground fit: {'; '.join(q['weak'])}" + ("" if placed else " (--up, --camera-height "
              "and --scale place the ground without the fit)"), file=sys.stderr)
    if info["external_images"]:
        print("note: the images stay outside the package; symdrive validate/run need --allow-external-assets "
              "(or import again with --copy-images)")
    return 0


def _colmap(args) -> int:
    import contextlib
    from pathlib import Path

    from ..importers.colmap import read_colmap
    from ..importers.undistort import undistorted

    t0 = time.perf_counter()
    _options(args)
    with undistorted(args.model, args.images, args.out) if args.undistort else contextlib.nullcontext() as und:
        model, images = (args.model, args.images) if und is None else (und.model, und.images)
        src = _with_lateral_truth(read_colmap(model, images, splats=args.splats, camera_name=args.camera_name,
                                              fps=args.fps), args)
        if und is not None:
            src.path = Path(args.model)
            src.notes["undistorted_cameras"] = und.cameras
            models = ", ".join(f"camera {cid} ({c['model']})" for cid, c in und.cameras.items())
            print(f"undistorted {sum(len(row) for row in src.grouped.table)} images of {models} to PINHOLE with "
                  f"COLMAP's undistorter ({time.perf_counter() - t0:.1f} s)")
        elif args.undistort:
            print("note: no camera has lens distortion; imported without undistorting")
        return _finish(src, args, t0, copy_images=und is not None)


def _nerfstudio(args) -> int:
    from ..importers.nerfstudio import read_nerfstudio
    from ..importers.undistort import undistorted_views

    t0 = time.perf_counter()
    _options(args)
    src = read_nerfstudio(args.transforms, splats=args.splats, camera_name=args.camera_name, fps=args.fps,
                          undistort=args.undistort)
    views = [v for row in src.grouped.table for v in row]
    lensed = sum(v.lens is not None for v in views)
    with undistorted_views(views, args.out) as cameras:
        if cameras is not None:
            src.notes["undistorted_cameras"] = cameras
            models = ", ".join(f"camera {cid} ({c['model']})" for cid, c in cameras.items())
            print(f"undistorted {lensed} images of {models} to PINHOLE with "
                  f"COLMAP's undistorter ({time.perf_counter() - t0:.1f} s)")
        elif args.undistort:
            print("note: no camera has lens distortion; imported without undistorting")
        return _finish(_with_lateral_truth(src, args), args, t0, copy_images=cameras is not None)


def _kitti(args) -> int:
    from dataclasses import replace

    import numpy as np

    from ..importers.ground import path_up
    from ..importers.kitti import read_kitti
    from ..importers.stereo import split_rig

    t0 = time.perf_counter()
    opt = _options(args)
    src, right = read_kitti(args.sequence, args.poses, splats=args.splats, camera_name=args.camera_name,
                            fps=args.fps)
    if right is None:
        print(f"one camera: {src.notes['image_folder']} (KITTI camera {src.notes['kitti_camera']}), no lateral "
              "ground truth")
    elif args.rig:
        print(f"a rig of two cameras: {args.camera_name} and {right}, both trained on")
    else:
        src.grouped, src.lateral = split_rig(src.grouped, right)
    # KITTI's poses are metric: scale 1, and the ground --camera-height below the cameras' median
    # height. Its plane is the one the camera path rides on (points need not be triangulated).
    c2ws = np.stack([v.c2w for v in src.grouped.table[0]])
    up = opt.up or tuple(path_up(c2ws).tolist())
    return _finish(src, args, t0, options=replace(opt, scale=opt.scale or 1.0, up=up))


def _kitti_raw(args) -> int:
    from dataclasses import replace

    from ..importers.kitti_raw import read_kitti_raw
    from . import given

    t0 = time.perf_counter()
    opt = _options(args)
    config = replace(KittiRawConfig(), **given(args, "cameras", "types"))
    drive = read_kitti_raw(args.drive, config, splats=args.splats, fps=args.fps, progress=not args.quiet)
    src = _with_lateral_truth(drive.source, args)
    if src.points is None:
        print("note: no velodyne_points/data: no LiDAR depth; the ground comes from points triangulated from the "
              "images", flush=True)
    return _finish_metric(src, args, t0, opt, drive.extend,
                          partial(_drive_report, boxes="tracklets", outside="in frames not imported", kinds="types"))


def _finish_metric(src, args, t0, opt, extend, report) -> int:
    """:func:`_finish` for a drive recorded with metric poses (OXTS, KITTI-360's world): scale 1
    unless --scale says otherwise, and without LiDAR points the ground's plane is the one the
    camera path rides on."""
    from dataclasses import replace

    import numpy as np

    from ..importers.ground import path_up

    c2ws = np.stack([v.c2w for v in src.grouped.table[0]])
    up = opt.up or (None if src.points is not None else tuple(path_up(c2ws).tolist()))
    return _finish(src, args, t0, options=replace(opt, scale=opt.scale or 1.0, up=up), extend=extend, report=report)


def _drive_report(extended: dict, boxes: str, outside: str | None, kinds: str) -> None:
    """What a recorded drive's LiDAR and boxes added to the package, in the drive's own words:
    ``boxes`` where the boxes came from, ``outside`` what those in no imported frame are (None:
    the reader keeps none), ``kinds`` what the classes left out are called."""
    _lidar_report(extended["lidar"])
    tracks = extended["tracks"]
    if tracks is None:
        return
    skipped = ", ".join(f"{kind} {n}" for kind, n in sorted(tracks["skipped"].items())) or "none"
    held = "" if outside is None else f" ({tracks['outside']} {outside})"
    print(f"{boxes}: {tracks['tracks']} vehicle(s) as existing actors, {tracks['boxes']} boxes{held}; {kinds} "
          f"skipped: {skipped}")
    _bad_tracks_warning(tracks["reported"])


def _bad_tracks_warning(reported: list[dict]) -> None:
    """One warning line naming every box the tracks import reported (actor and frame)."""
    if reported:
        print(f"warning: {len(reported)} tracked box(es) are not a plausible motion (the reconstruction does not "
              f"smooth its pose corrections across them): {'; '.join(r['message'] for r in reported)}", file=sys.stderr)


def _lidar_report(lidar: list[dict]) -> None:
    for info in lidar:
        print(f"LiDAR depth for camera {info['camera']} in {info['folder']}/: {info['points']} points, "
              f"{100 * info['measured_fraction']:.1f}% of pixels measured")


def _nuscenes(args) -> int:
    from dataclasses import replace

    from ..importers.nuscenes import read_nuscenes
    from . import given

    t0 = time.perf_counter()
    opt = _options(args)
    config = replace(NuScenesConfig(), **given(args, "version", "cameras"))
    scene = read_nuscenes(args.dataroot, args.scene, config, splats=args.splats, progress=not args.quiet)
    # nuScenes' global frame is metric; the ground is fitted to the LiDAR's returns.
    return _finish(scene.source, args, t0, options=replace(opt, scale=opt.scale or 1.0), extend=scene.extend,
                   report=partial(_drive_report, boxes="annotations", outside=None, kinds="categories"))


def _kitti360(args) -> int:
    from dataclasses import replace

    from ..importers.kitti360 import read_kitti360
    from . import given

    t0 = time.perf_counter()
    opt = _options(args)
    fields = given(args, "cameras", "types", "frames")
    if "frames" in fields:
        fields["frames"] = tuple(fields["frames"])
    seq = read_kitti360(args.root, args.sequence, replace(Kitti360Config(), **fields), splats=args.splats,
                        fps=args.fps, progress=not args.quiet)
    src = _with_lateral_truth(seq.source, args)
    n = src.notes["frames_without_pose"]
    if n:
        print(f"{n} frame(s) with images but no pose in {src.notes['poses']} left out (the first: "
              f"{', '.join(src.notes['frames_without_pose_first'])})", flush=True)
    if src.points is None:
        print("note: no data_3d_raw velodyne scans: no LiDAR depth; the ground's plane is the camera path's", flush=True)
    return _finish_metric(src, args, t0, opt, seq.extend,
                          partial(_drive_report, boxes="3D boxes", outside="box(es) in no imported frame",
                                  kinds="classes"))


def _gs(args) -> int:
    from ..importers.gs_trainer import read_gs_output

    t0 = time.perf_counter()
    _options(args)
    src = read_gs_output(args.model, args.images, iteration=args.iteration, splats=args.splats,
                         camera_name=args.camera_name, fps=args.fps)
    return _finish(src, args, t0)


def _lidar(args) -> int:
    from dataclasses import replace

    from ..errors import InputError
    from ..importers.lidar import LidarConfig, import_lidar

    t0 = time.perf_counter()
    config = LidarConfig()
    if args.min_depth is not None:
        if not args.min_depth >= 0:
            raise InputError("--min-depth", f"expected a distance >= 0 in metres, got {args.min_depth}")
        config = replace(config, min_depth_m=args.min_depth)
    info = import_lidar(args.package, args.scans, args.sensor_to_camera, camera=args.camera,
                        kitti_camera=args.kitti_camera, force=args.force, config=config, progress=not args.quiet)
    print(f"sensor to camera: {info['calibration']}")
    print(f"{info['package']}: sparse depth for camera {info['camera']} in {info['folder']}/ from {info['frames']} "
          f"scans ({info['points']} points, {100 * info['measured_fraction']:.1f}% of pixels measured; "
          f"{time.perf_counter() - t0:.1f} s)")
    return 0


def _tracks(args) -> int:
    from dataclasses import replace

    from ..errors import InputError
    from ..importers.tracks import import_tracks, tracks_format
    from . import given

    t0 = time.perf_counter()
    if tracks_format(args.tracks, args.tracks_format) != "kitti":
        for flag, value in (("--types", args.types), ("--calib", args.calib)):
            if value is not None:
                raise InputError(args.tracks, f"{flag} is for KITTI labels; this is a JSON tracks file", flag)
    config = replace(TracksConfig(), **given(args, "types", "frame_offset"))
    info = import_tracks(args.package, args.tracks, fmt=args.tracks_format, camera=args.camera, calib=args.calib,
                         replace=args.replace, config=config)
    skipped = ", ".join(f"{kind} {n}" for kind, n in sorted(info["skipped"].items())) or "none"
    print(f"{info['package']}: {info['tracks']} tracks as existing actors ({info['replaced']} replacing actors), "
          f"{info['boxes']} boxes; {info['outside']} boxes outside the package's frames 0..{info['frames'] - 1} "
          f"({info['tracks_outside']} tracks with none inside, not added); types skipped: {skipped} "
          f"({time.perf_counter() - t0:.1f} s)")
    _bad_tracks_warning(info["reported"])
    return 0
