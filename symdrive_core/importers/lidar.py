"""LiDAR scans -> sparse depth maps of a package camera (``symdrive import lidar``).

A recorded drive's LiDAR is the depth a reconstruction and the geometry-guided warp can trust,
but it measures a few pixels of each image, not all of them. One scan per package frame (in
name order, numbers compared as numbers): KITTI's ``velodyne`` ``.bin`` (float32 x, y, z,
reflectance), nuScenes' ``.pcd.bin`` (float32 x, y, z, intensity, ring), an ``.npz`` whose
``points`` array is [N, 3 to 16], or a PLY with x, y, z. Points move into the camera by the rig's
fixed sensor-to-camera transform (:func:`write_depth` also takes one per frame, for a LiDAR and a
camera that record at different times on a moving vehicle) and are projected with each frame's
K; a pixel keeps its nearest point (a z-buffer: a return through a gap behind a pole is hidden by
the pole). Maps are float EXR under ``lidar_depth/<camera>/``, 0 where no point landed,
and the camera is declared ``depth_zero: "unmeasured"`` (see :mod:`..scene.depth`) so no reader
takes the gaps for sky. Depths are in the scan's metres: the package's world must be metric
(import it with ``--camera-height`` or ``--scale``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import conventions
from ..errors import InputError
from ..io import check_regular
from .calib_text import finite_numbers, read_small_text, rigid_transform
from .frames import natural_key
from .kitti_calib import CAMERAS, REFERENCE_CAMERA, labels_of, layout_of, velo_to_camera

SCAN_SUFFIXES = (".bin", ".npz", ".ply")
DEPTH_FOLDER = "lidar_depth"
MAX_POINT_FIELDS = 16  # values per point in an .npz scan (x, y, z, intensity, ring, time, ...): more is a transpose
MAX_SCAN_BYTES = 1 << 30  # a 128-beam scan is tens of MB; this stops a hostile file, not a real one


@dataclass(frozen=True)
class LidarConfig:
    # Returns nearer to the camera than this (metres) are dropped: the ego vehicle, spray, noise.
    min_depth_m: float = 0.5


def read_scan(path: Path) -> np.ndarray:
    """The finite points [N, 3] (float64, sensor frame) of one scan; rows with NaN or inf, which
    drivers write for beams without a return, are dropped."""
    path = Path(path)
    size = check_regular(path, "points").st_size
    if size > MAX_SCAN_BYTES:
        raise InputError(path, f"{size} bytes; scans above {MAX_SCAN_BYTES} bytes are not read", "points")
    suffix = path.suffix.lower()
    if suffix == ".bin":
        nuscenes = path.name.lower().endswith(".pcd.bin")
        record, fields = (20, "nuScenes records (float32 x, y, z, intensity, ring)") if nuscenes else \
            (16, "KITTI records (float32 x, y, z, reflectance)")
        if size % record:
            raise InputError(path, f"{size} bytes is not a whole number of {fields}", "points")
        if not size:
            raise InputError(path, f"0 bytes: no {fields} (a scan cut off in copying?)", "points")
        points = np.fromfile(path, dtype="<f4").reshape(-1, record // 4)[:, :3]
    elif suffix == ".npz":
        points = _npz_points(path)
    elif suffix == ".ply":
        from ..io.ply import read_header, read_vertex_table

        table = read_vertex_table(path, read_header(path))
        missing = [c for c in "xyz" if c not in table.dtype.names]
        if missing:
            raise InputError(path, f"scan lacks {', '.join(missing)}", "element vertex")
        points = np.stack([table[c] for c in "xyz"], 1)
    else:
        raise InputError(path, f"unknown scan format; expected one of {', '.join(SCAN_SUFFIXES)}", "points")
    points = np.asarray(points, dtype=np.float64)
    return points[np.isfinite(points).all(1)]


def _npz_points(path: Path) -> np.ndarray:
    import zipfile

    try:
        with np.load(path, allow_pickle=False) as z:
            if "points" not in z.files:
                has = ", ".join(z.files) or "nothing"
                raise InputError(path, f"no 'points' array (has: {has})", "points")
            points = z["points"]
    except (ValueError, OSError, zipfile.BadZipFile) as exc:
        raise InputError(path, f"not a readable .npz: {exc}", "points") from None
    if points.ndim != 2 or not 3 <= points.shape[1] <= MAX_POINT_FIELDS or points.dtype.kind not in "fiu":
        transposed = points.ndim == 2 and points.shape[0] >= 3 and points.shape[1] > MAX_POINT_FIELDS
        raise InputError(path, f"expected numbers [N, 3 to {MAX_POINT_FIELDS}] (a row per point), got {points.dtype} "
                         f"{list(points.shape)}" + (" (a column per point? transpose it)" if transposed else ""), "points")
    return points[:, :3]


def read_sensor_to_camera(path: Path, kitti_camera: int | None = None) -> tuple[np.ndarray, str]:
    """(the rig's rigid sensor-to-camera transform [4, 4], a line saying how it was read) from a
    text file: 12 or 16 numbers (a row-major 3x4 or 4x4) into the package camera, or a KITTI
    calibration file of any layout (:mod:`.kitti_calib`) composed to KITTI camera ``kitti_camera``
    (None: camera 0, and the line says so)."""
    path = Path(path)
    text = read_small_text(path, "--sensor-to-camera")
    labels = labels_of(text)
    if layout_of(labels) is not None:
        T, how = velo_to_camera(path, labels, REFERENCE_CAMERA if kitti_camera is None else kitti_camera)
        if kitti_camera is None:
            how += "; the package does not say which KITTI camera it holds: camera 0 (--kitti-camera N for another)"
        return T, how
    text = "\n".join(line.split("#", 1)[0] for line in text.splitlines())
    count = len(text.replace(",", " ").split())
    v = finite_numbers(text, 16 if count == 16 else 12, path, "transform")
    return rigid_transform(v, path, "transform"), f"{len(v)} numbers: the transform into the package camera as written"


def landing(points: np.ndarray, sensor_to_camera: np.ndarray, K: np.ndarray, width: int, height: int,
            min_depth_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(indices of the ``points`` that land in the image at least ``min_depth_m`` ahead, their
    pixel rows, columns and camera z). Pixel (0, 0) covers [0, 1)^2
    (``conventions.PIXEL_CENTER_OFFSET``)."""
    uv, z = conventions.project_points(points, sensor_to_camera, K)
    keep = np.flatnonzero((z >= min_depth_m) & np.isfinite(uv).all(1))
    col = np.floor(uv[keep, 0]).astype(np.int64)
    row = np.floor(uv[keep, 1]).astype(np.int64)
    inside = (col >= 0) & (col < width) & (row >= 0) & (row < height)
    keep = keep[inside]
    return keep, row[inside], col[inside], z[keep]


def sparse_depth(points: np.ndarray, sensor_to_camera: np.ndarray, K: np.ndarray, width: int, height: int,
                 min_depth_m: float) -> np.ndarray:
    """Camera z-depth [H, W] (float32) of the nearest point landing in each pixel, 0 where none
    does (:func:`landing`)."""
    _, row, col, z = landing(points, sensor_to_camera, K, width, height, min_depth_m)
    depth = np.full(width * height, np.inf)
    np.minimum.at(depth, row * width + col, z)
    depth[np.isinf(depth)] = 0.0
    return depth.reshape(height, width).astype(np.float32)


def seen_returns(scans: list[Path], world_from_sensor, sensor_to_camera, K: np.ndarray, width: int, height: int,
                 images: list[Path], count: int, min_depth_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points [N, 3] in the world of ``world_from_sensor[i]``, colours [N, 3], the scan ``i`` of
    each [N]): of each scan
    ``scans[i]`` an even share of ``count`` of the returns that land in a camera's image
    (``sensor_to_camera[i]``, ``K``, ``width`` x ``height``), each coloured from ``images[i]`` where
    it lands. A drive's metric points (the ground under the path, where the reconstruction starts)
    with the colours its camera saw; the sample is seeded, so an import is repeatable."""
    from ..io.images import read_image

    rng = np.random.default_rng(0)
    share = -(-count // len(scans))
    points, colors, frames = [], [], []
    for i, (scan, image, w_sensor, s_to_c) in enumerate(zip(scans, images, world_from_sensor, sensor_to_camera)):
        p = read_scan(scan)
        keep, row, col, _ = landing(p, s_to_c, K, width, height, min_depth_m)
        if len(keep) > share:
            pick = np.sort(rng.choice(len(keep), share, replace=False))
            keep, row, col = keep[pick], row[pick], col[pick]
        rgb = read_image(image, channels=3)
        colors.append(rgb[row, col])
        points.append(p[keep] @ w_sensor[:3, :3].T + w_sensor[:3, 3])
        frames.append(np.full(len(keep), i))
    return np.concatenate(points), np.concatenate(colors).astype(np.float64), np.concatenate(frames)


def list_scans(folder: Path) -> list[Path]:
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(folder, "not a folder of scans", "SCANS_DIR")
    scans = [p for p in folder.iterdir() if p.suffix.lower() in SCAN_SUFFIXES and not p.name.startswith(".")]
    return sorted(scans, key=lambda p: natural_key(p.name))


def import_lidar(package, scans_dir, calibration, *, camera: str | None = None, kitti_camera: int | None = None,
                 force: bool = False, config: LidarConfig = LidarConfig(), progress: bool = True) -> dict:
    """Write one sparse depth map per frame of ``camera`` (default: the package's first) from the
    scans in ``scans_dir``, moved into the camera by the ``calibration`` file
    (:func:`read_sensor_to_camera`; a KITTI one composed to ``kitti_camera``, else to the KITTI
    camera the package's source notes, else to camera 0), as :func:`write_depth` does. Returns a
    summary (frames, points, measured fraction, how the calibration was read)."""
    from ..scene import load_manifest

    m = load_manifest(package)
    where = m.path or m.root
    try:
        cam = m.camera(camera) if camera else m.cameras[0]
    except KeyError:
        raise InputError(where, f"no camera named {camera!r} (has: {', '.join(c.name for c in m.cameras)})",
                         "--camera") from None
    held = m.source.get("kitti_camera")
    if kitti_camera is None and held is not None:
        if isinstance(held, bool) or not isinstance(held, int) or held not in CAMERAS:
            raise InputError(where, f"not a KITTI camera ({', '.join(map(str, CAMERAS))}): {held!r}",
                             "source.kitti_camera")
        kitti_camera = held
    sensor_to_camera, how = read_sensor_to_camera(calibration, kitti_camera)
    scans = list_scans(scans_dir)
    if len(scans) != len(cam.frames):
        raise InputError(scans_dir, f"{len(scans)} scans ({', '.join(SCAN_SUFFIXES)}) for {len(cam.frames)} "
                                    "package frames: expected one scan per frame", "SCANS_DIR")
    info = write_depth(m, cam, scans, [sensor_to_camera] * len(scans), force=force, config=config,
                       progress=progress)
    return {**info, "calibration": how}


def write_depth(m, cam, scans: list[Path], sensor_to_camera, *, force: bool = False,
                config: LidarConfig = LidarConfig(), progress: bool = True) -> dict:
    """Write frame ``i``'s sparse depth map of camera ``cam`` of the loaded package ``m`` from
    ``scans[i]`` moved into the camera by ``sensor_to_camera[i]`` [4, 4] (a rig's fixed transform
    each frame, or the sensor's and the camera's poses each at its own time when the vehicle moves
    between them), point the camera's frames at them and save the manifest. The maps are written
    whole into the package (a temporary folder renamed into place) before the manifest names them;
    bad input leaves the package as it was. Returns a summary (frames, points, measured fraction)."""
    from tqdm import tqdm

    from ..io.atomic import atomic_directory
    from ..io.images import write_image
    from ..scene import is_inside

    where = m.path or m.root
    ci = m.cameras.index(cam)
    if not force and any(cf.depth is not None for cf in cam.frames):
        first = next(i for i, cf in enumerate(cam.frames) if cf.depth is not None)
        raise InputError(where, f"camera {cam.name!r} already has depth maps; pass --force to replace them",
                         f"cameras[{ci}].frames[{first}].depth")
    folder = m.root / DEPTH_FOLDER / cam.name
    if not is_inside(folder.parent, m.root):
        raise InputError(where, f"{DEPTH_FOLDER}/ leads outside the package (a symlink)", DEPTH_FOLDER)
    if folder.parent.exists() and not folder.parent.is_dir():
        raise InputError(folder.parent, "is a file; the depth maps go in a folder of that name", DEPTH_FOLDER)
    if folder.exists() and not force:
        raise InputError(folder, "already exists; pass --force to replace it", "--force")
    points, coverage = 0, []
    new_parent = not folder.parent.exists()
    try:
        with atomic_directory(folder) as tmp:
            for fi, scan in enumerate(tqdm(scans, desc="lidar", unit="scan", disable=not progress)):
                cf = cam.frames[fi]
                pts = read_scan(scan)
                depth = sparse_depth(pts, sensor_to_camera[fi], cf.K, cam.width, cam.height, config.min_depth_m)
                write_image(tmp / f"{fi:06d}.exr", depth, dtype="float")
                points += len(pts)
                coverage.append(float((depth > 0).mean()))
    except BaseException:
        if new_parent:
            folder.parent.rmdir()  # the folder atomic_directory made for the temporary one
        raise
    for fi, cf in enumerate(cam.frames):
        cf.depth = f"{DEPTH_FOLDER}/{cam.name}/{fi:06d}.exr"
    cam.depth_zero = "unmeasured"
    m.save()
    return {"package": str(m.root), "camera": cam.name, "frames": len(scans), "points": points,
            "measured_fraction": float(np.mean(coverage)), "folder": f"{DEPTH_FOLDER}/{cam.name}"}
