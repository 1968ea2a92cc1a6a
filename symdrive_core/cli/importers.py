"""``symdrive import colmap|nerfstudio|3dgs``: a reconstruction of a recorded drive -> a scene package."""

from __future__ import annotations

import time

from ..importers.frames import DEFAULT_CAMERA, DEFAULT_FPS
from . import add_quiet_option, count_int, positive_int


def _common(p, images: bool) -> None:
    if images:
        p.add_argument("--images", help="folder of the recorded images (paths in the model are relative to it)")
    p.add_argument("--out", required=True, help="scene package folder to write (written whole, or not at all)")
    p.add_argument("--splats", help="trained 3DGS splat PLY in the same frame as the cameras")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--camera-height", type=float,
                   help="the cameras' height above the ground in metres (sets the metric scale)")
    g.add_argument("--scale", type=float, help="metres per source unit (instead of --camera-height)")
    p.add_argument("--up", help="the world's up direction x,y,z in the source frame (default: fitted ground "
                                "plane, checked against the cameras' mean up vector)")
    p.add_argument("--heldout-every", type=positive_int, metavar="N",
                   help="hold every N-th frame out of training for evaluation (N=5: frames 2, 7, 12, ...)")
    p.add_argument("--copy-images", action="store_true",
                   help="copy the images into the package (default: reference them, relative to the package)")
    p.add_argument("--camera-name", default=DEFAULT_CAMERA,
                   help=f"name of the package camera when there is one ({DEFAULT_CAMERA})")
    p.add_argument("--fps", type=float, default=DEFAULT_FPS,
                   help=f"frame rate for timestamps when the source has none ({DEFAULT_FPS:g})")
    p.add_argument("--name", help="scene name (default: the package folder's name)")
    p.add_argument("--force", action="store_true", help="replace --out if it exists")
    add_quiet_option(p)


def add_commands(sub) -> None:
    imp = sub.add_parser("import", help="turn a COLMAP, nerfstudio or 3DGS reconstruction, or a KITTI sequence, into "
                                        "a scene package")
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
    p = isub.add_parser("kitti", help="KITTI odometry sequence (rectified stereo pair, calib.txt, poses): the left "
                                      "camera, the right one as lateral ground truth")
    p.add_argument("sequence", metavar="SEQUENCE_DIR",
                   help="folder with image_2/image_3 (or image_0/image_1, image_l/image_r) and calib.txt")
    p.add_argument("--poses", help="the sequence's poses file, metres (default: SEQUENCE_DIR/poses.txt)")
    _common(p, images=False)
    p.set_defaults(func=_kitti)
    p = isub.add_parser("3dgs", help="the original 3DGS trainer's output folder (cameras.json, point_cloud/)")
    p.add_argument("model", metavar="MODEL_DIR", help="the 3DGS trainer's output folder (cameras.json, point_cloud/)")
    _common(p, images=True)
    p.add_argument("--iteration", type=count_int, help="point_cloud/iteration_N to use (default: the newest)")
    p.set_defaults(func=_gs)


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

    if args.camera_height is not None and not args.camera_height > 0:
        raise InputError("--camera-height", f"expected a positive height in metres, got {args.camera_height}")
    if args.scale is not None and not args.scale > 0:
        raise InputError("--scale", f"expected a positive number, got {args.scale}")
    if args.heldout_every is not None and args.heldout_every < 2:
        raise InputError("--heldout-every", f"expected N >= 2, got {args.heldout_every}")
    if not args.fps > 0:
        raise InputError("--fps", f"expected a positive frame rate, got {args.fps}")
    return Options(out=Path(args.out), camera_height=args.camera_height, scale=args.scale, up=parse_up(args.up),
                   heldout_every=args.heldout_every, copy_images=args.copy_images or copy_images, force=args.force, name=args.name)


def _finish(src, args, t0, copy_images: bool = False, options=None) -> int:
    from ..importers.package import write_package

    info = write_package(src, options or _options(args, copy_images), progress=not args.quiet)
    print(f"{info['package']}: {info['frames']} frames, cameras {', '.join(info['cameras'])}, "
          f"scale {info['scale']:.6g} m per source unit, camera height {info['camera_height_m']:.3f} m "
          f"({time.perf_counter() - t0:.1f} s)")
    if src.lateral is not None:
        print(f"lateral ground truth: camera {src.lateral.name}, {len(src.lateral.views)} images at "
              f"{info['lateral_offset_m']:+g} m of camera {src.lateral.camera} (not trained on)")
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

    from ..importers.ground import camera_up_vectors
    from ..importers.kitti import read_kitti
    from ..importers.stereo import split_rig

    t0 = time.perf_counter()
    opt = _options(args)
    src, right = read_kitti(args.sequence, args.poses, splats=args.splats, camera_name=args.camera_name,
                            fps=args.fps)
    src.grouped, src.lateral = split_rig(src.grouped, right)
    # KITTI's poses are metric: scale 1. Without points or splats to fit a ground to, the up direction
    # is the cameras' mean up vector and the ground lies --camera-height below the lowest camera.
    c2ws = [v.c2w for v in src.grouped.table[0]]
    up = opt.up or tuple(camera_up_vectors(c2ws).mean(0).tolist())
    return _finish(src, args, t0, options=replace(opt, scale=opt.scale or 1.0, up=up))


def _gs(args) -> int:
    from ..importers.gs_trainer import read_gs_output

    t0 = time.perf_counter()
    _options(args)
    src = read_gs_output(args.model, args.images, iteration=args.iteration, splats=args.splats,
                         camera_name=args.camera_name, fps=args.fps)
    return _finish(src, args, t0)
