"""nerfstudio ``transforms.json`` -> :class:`~.package.Source`.

Poses (``transform_matrix``) are camera-to-world with OpenGL camera axes (x right, y up, z back);
they become OpenCV by flipping the camera's y and z. Intrinsics (``fl_x``, ``fl_y``, ``cx``, ``cy``,
``w``, ``h``) come from the frame when it has them, else from the top level. ``applied_transform``
(3x4, written by ``ns-process-data``) maps the original reconstruction's frame (COLMAP's) to the
frame of these poses and of ``ply_file_path``; the package's ``source.transform`` maps that
original frame, and ``source.poses_transform`` the poses' frame, to the package world. A splat PLY
(``--splats``) is taken to be in the poses' frame. Lens distortion other than zero is refused, or
kept as the view's COLMAP lens (``undistort``) for :mod:`.undistort` to resample.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .. import conventions
from ..errors import InputError
from .frames import DEFAULT_CAMERA, DEFAULT_FPS, View, group_views, named_file
from .package import Source

GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])
DISTORTION_KEYS = ("k1", "k2", "k3", "k4", "p1", "p2")
SUPPORTED_MODELS = ("OPENCV", "PINHOLE", "SIMPLE_PINHOLE", "OPENCV_FISHEYE")


def _num(d: dict, key: str, path: Path, where: str):
    v = d.get(key)
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
        raise InputError(path, f"expected a finite number, got {v!r}", f"{where}.{key}")
    return float(v)


def _matrix(v, rows: int, path: Path, where: str) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if a.shape not in ((rows, 4), (4, 4)):
        raise InputError(path, f"expected a {rows}x4 matrix", where)
    if not np.all(np.isfinite(a)):
        raise InputError(path, "pose is not finite (NaN or Inf)", where)
    out = np.eye(4)
    out[:a.shape[0]] = a
    return out


def colmap_lens(model: str, intr: dict, path: Path, where: str) -> tuple[str, list[float]]:
    """The COLMAP camera model and parameters of a nerfstudio camera with lens distortion."""
    k = {key: intr[key] or 0.0 for key in DISTORTION_KEYS}
    fx, fy = intr["fl_x"], intr["fl_y"] if intr["fl_y"] is not None else intr["fl_x"]
    head = [fx, fy, intr["cx"], intr["cy"]]
    if model == "OPENCV_FISHEYE":
        if k["p1"] or k["p2"]:
            raise InputError(path, "a fisheye camera has no tangential distortion", f"{where}.p1")
        return "OPENCV_FISHEYE", head + [k["k1"], k["k2"], k["k3"], k["k4"]]
    if k["k4"]:
        raise InputError(path, f"camera model {model} has no k4 (OPENCV_FISHEYE has)", f"{where}.k4")
    if k["k3"]:
        return "FULL_OPENCV", head + [k["k1"], k["k2"], k["p1"], k["p2"], k["k3"], 0.0, 0.0, 0.0]
    return "OPENCV", head + [k["k1"], k["k2"], k["p1"], k["p2"]]


def read_views(transforms: str | Path, *, undistort: bool = False) -> tuple[Path, dict, np.ndarray, list[View]]:
    """(the transforms.json read, its JSON, applied_transform or identity, its views): poses and
    intrinsics only, nothing else read (the add-on's *Import Recorded Drive* uses this).
    ``undistort``: views with lens distortion keep it as their ``lens`` instead of being refused."""
    path = Path(transforms)
    if path.is_dir():
        path = path / "transforms.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8-sig"))
    except FileNotFoundError:
        raise InputError(path, "file not found", "transforms.json") from None
    except (UnicodeDecodeError, RecursionError, ValueError) as exc:  # ValueError: JSON's, a number of thousands of digits
        raise InputError(path, f"not valid JSON: {exc}") from None
    if not isinstance(data, dict) or not isinstance(data.get("frames"), list):
        raise InputError(path, "expected an object with a 'frames' list", "frames")
    if not data["frames"]:
        raise InputError(path, "empty: no frames", "frames")
    base = path.parent
    A = np.eye(4)
    if data.get("applied_transform") is not None:
        A = _matrix(data["applied_transform"], 3, path, "applied_transform")
        Ra = A[:3, :3] / np.cbrt(np.linalg.det(A[:3, :3])) if np.linalg.det(A[:3, :3]) > 0 else None
        if Ra is None or not np.allclose(Ra @ Ra.T, np.eye(3), atol=1e-5):
            raise InputError(path, "not a similarity (scaled rotation)", "applied_transform")
    views = []
    for i, f in enumerate(data["frames"]):
        where = f"frames[{i}]"
        if not isinstance(f, dict):
            raise InputError(path, "expected an object", where)
        model = f.get("camera_model", data.get("camera_model", "OPENCV"))
        if model not in SUPPORTED_MODELS or (model == "OPENCV_FISHEYE" and not undistort):
            hint = "; import it with --undistort" if model == "OPENCV_FISHEYE" else ""
            raise InputError(path, f"camera model {model!r} is not imported (pinhole cameras only{hint})",
                             f"{where}.camera_model")
        intr = {}
        for key in ("fl_x", "fl_y", "cx", "cy", "w", "h", *DISTORTION_KEYS):
            v = _num(f, key, path, where)
            if v is None:
                v = _num(data, key, path, "(top level)")
            intr[key] = v
        missing = [k for k in ("fl_x", "cx", "cy", "w", "h") if intr[k] is None]
        if missing:
            raise InputError(path, f"no {', '.join(missing)} in the frame or at the top level", where)
        lens = None
        if any(intr[k] for k in DISTORTION_KEYS) or model == "OPENCV_FISHEYE":
            nz = [k for k in DISTORTION_KEYS if intr[k]] or ["k1"]
            if not undistort:
                raise InputError(path, f"camera model {model} with lens distortion ({', '.join(nz)} non-zero) is "
                                 "not imported; import it with 'symdrive import nerfstudio ... --undistort'",
                                 f"{where}.{nz[0]}")
            lens = colmap_lens(model, intr, path, where)
        fy = intr["fl_y"] if intr["fl_y"] is not None else intr["fl_x"]
        K = conventions.intrinsics(intr["fl_x"], fy, intr["cx"], intr["cy"])
        fp = f.get("file_path")
        if not isinstance(fp, str) or not fp:
            raise InputError(path, f"expected an image path, got {fp!r}", f"{where}.file_path")
        if "transform_matrix" not in f:
            raise InputError(path, "required field is missing", f"{where}.transform_matrix")
        c2w = _matrix(f["transform_matrix"], 3, path, f"{where}.transform_matrix") @ GL_TO_CV
        t = f.get("timestamp", f.get("time"))
        if t is not None and (isinstance(t, bool) or not isinstance(t, (int, float))):
            raise InputError(path, f"expected a number, got {t!r}", f"{where}.timestamp")
        name = Path(fp).as_posix()
        if name.startswith("./"):
            name = name[2:]
        views.append(View(name=name, K=K, width=int(intr["w"]), height=int(intr["h"]), c2w=c2w, source=path,
                          where=where, image=named_file(base, fp, path, f"{where}.file_path"),
                          timestamp=None if t is None else float(t), lens=lens))
    # Views' folder layout is {camera}/{frame} when the dataset has one folder per camera; a single
    # images/ folder is one camera.
    if views and all(v.name.startswith("images/") for v in views):
        for v in views:
            v.name = v.name[len("images/"):]
    return path, data, A, views


def read_nerfstudio(transforms: str | Path, *, splats: str | Path | None = None, camera_name: str = DEFAULT_CAMERA,
                    fps: float = DEFAULT_FPS, undistort: bool = False) -> Source:
    path, data, A, views = read_views(transforms, undistort=undistort)
    base = path.parent
    points = colors = None
    ply = data.get("ply_file_path")
    if isinstance(ply, str) and ply:
        from ..io.points import read_points

        ply_path = named_file(base, ply, path, "ply_file_path")
        if not ply_path.is_file():
            raise InputError(path, f"file not found: {ply}", "ply_file_path")
        p, c = read_points(ply_path)
        points, colors = p.astype(np.float64), c.astype(np.float64)
    g = None
    if splats is not None:
        from ..io.ply import read_splats

        g = read_splats(splats)
    return Source("nerfstudio", path, group_views(views, camera_name=camera_name, fps=fps), splats=g,
                  splats_path=None if splats is None else Path(splats), points=points, colors=colors,
                  pre=None if data.get("applied_transform") is None else A)
