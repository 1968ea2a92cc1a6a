"""COLMAP sparse models (text or binary, read through pycolmap) -> :class:`~.package.Source`.

COLMAP stores world-to-camera poses with OpenCV camera axes and puts pixel centres at +0.5, the
package's conventions, so poses invert and ``PINHOLE``/``SIMPLE_PINHOLE`` parameters map straight
to ``K``. Models with lens distortion are refused naming the model, unless every distortion
coefficient is zero; :mod:`.undistort` turns them into PINHOLE models (``--undistort``).
"""

from __future__ import annotations

import contextlib
import sys
from pathlib import Path

import numpy as np

from .. import conventions
from ..errors import InputError
from .frames import DEFAULT_CAMERA, DEFAULT_FPS, View, group_views, named_file
from .package import Source

PINHOLE_MODELS = ("PINHOLE", "SIMPLE_PINHOLE")


def load_pycolmap():
    """pycolmap, or one line saying how to install it into this very Python (Blender's too)."""
    # pycolmap's wheel links its own zlib and libpng with visible symbols; loaded before
    # OpenImageIO it takes over OpenImageIO's PNG writer, which then crashes (double free).
    with contextlib.suppress(ImportError):
        import OpenImageIO  # noqa: F401
    try:
        import pycolmap
    except ImportError:
        raise InputError("pycolmap", f'not installed; COLMAP models are read through it: "{sys.executable}" -m pip '
                         "install pycolmap") from None
    return pycolmap


def model_file(model_dir: Path, stem: str) -> Path:
    for ext in (".bin", ".txt"):
        if (model_dir / f"{stem}{ext}").is_file():
            return model_dir / f"{stem}{ext}"
    return model_dir / f"{stem}.bin"


def read_model(model_dir: str | Path):
    model_dir = Path(model_dir)
    if not model_dir.is_dir():
        raise InputError(model_dir, "not a folder (expected a COLMAP model: cameras, images, points3D)", "MODEL_DIR")
    for stem in ("cameras", "images"):
        f = model_file(model_dir, stem)
        if not f.is_file():
            raise InputError(f, f"missing: a COLMAP model needs {stem}.bin or {stem}.txt", stem)
    pycolmap = load_pycolmap()
    try:
        return pycolmap.Reconstruction(str(model_dir))
    except Exception as exc:  # pycolmap raises plain RuntimeError/ValueError on a malformed model
        msg = " ".join(str(exc).split())[:300]
        raise InputError(model_dir, f"cannot read the COLMAP model: {msg}", "model") from None


def model_name(cam) -> str:
    return cam.model_name if hasattr(cam, "model_name") else str(cam.model).split(".")[-1]


def pinhole_K(cam) -> np.ndarray | None:
    """``K`` of a camera without lens distortion, None for one with distortion."""
    name = model_name(cam)
    p = np.asarray(cam.params, dtype=np.float64)
    if name == "PINHOLE":
        return conventions.intrinsics(p[0], p[1], p[2], p[3])
    if name == "SIMPLE_PINHOLE":
        return conventions.intrinsics(p[0], p[0], p[1], p[2])
    # A distorted model whose distortion is all zero is a pinhole camera.
    if name in ("OPENCV", "FULL_OPENCV") and not np.any(p[4:]):
        return conventions.intrinsics(p[0], p[1], p[2], p[3])
    if name in ("SIMPLE_RADIAL", "RADIAL") and not np.any(p[3:]):
        return conventions.intrinsics(p[0], p[0], p[1], p[2])
    return None


def camera_K(cam, where: str, source: Path) -> np.ndarray:
    K = pinhole_K(cam)
    if K is None:
        raise InputError(source, f"camera model {model_name(cam)} has lens distortion; import it with "
                         "'symdrive import colmap ... --undistort' (COLMAP's undistorter writes PINHOLE cameras "
                         "and undistorted images into the package)", where)
    return K


def read_colmap(model_dir: str | Path, images: str | Path | None, *, splats: str | Path | None = None,
                camera_name: str = DEFAULT_CAMERA, fps: float = DEFAULT_FPS) -> Source:
    model_dir = Path(model_dir)
    rec = read_model(model_dir)
    cam_file, img_file = model_file(model_dir, "cameras"), model_file(model_dir, "images")
    images = Path(images) if images is not None else None
    Ks = {}
    for cid, cam in rec.cameras.items():
        Ks[cid] = (camera_K(cam, f"camera_id {cid}", cam_file), int(cam.width), int(cam.height))
    views = []
    for iid, im in sorted(rec.images.items()):
        where = f"image_id {iid} ({im.name})"
        if not getattr(im, "has_pose", True):
            continue
        pose = im.cam_from_world() if callable(im.cam_from_world) else im.cam_from_world
        w2c = np.eye(4)
        w2c[:3, :4] = np.asarray(pose.matrix(), dtype=np.float64)
        if not np.all(np.isfinite(w2c)):
            raise InputError(img_file, "pose is not finite (NaN or Inf)", where)
        if im.camera_id not in Ks:
            raise InputError(img_file, f"camera_id {im.camera_id} is not in {cam_file.name}", where)
        K, w, h = Ks[im.camera_id]
        views.append(View(name=im.name, K=K, width=w, height=h, c2w=conventions.invert_rigid(w2c),
                          source=img_file, where=where,
                          image=None if images is None else named_file(images, im.name, img_file, where),
                          camera_id=str(im.camera_id)))
    if not views:
        raise InputError(img_file, "empty model: no registered images", "images")
    pts = rec.points3D
    points = colors = None
    if len(pts):
        points = np.array([p.xyz for p in pts.values()], dtype=np.float64)
        colors = np.array([p.color for p in pts.values()], dtype=np.float64) / 255.0
    g = None
    if splats is not None:
        from ..io.ply import read_splats

        g = read_splats(splats)
    return Source("colmap", model_dir, group_views(views, camera_name=camera_name, fps=fps), splats=g,
                  splats_path=None if splats is None else Path(splats), points=points, colors=colors)
