"""The original 3DGS trainer's output folder -> :class:`~.package.Source`.

The folder holds ``cameras.json`` (per camera: ``img_name`` without extension, ``width``,
``height``, ``position`` = camera centre, ``rotation`` = camera-to-world rotation with OpenCV
axes, as the trainer derives them from COLMAP, ``fx``, ``fy``; the principal point is the image
centre), ``cfg_args`` (the trainer's arguments as a Python ``Namespace(...)`` repr, read without
evaluating it: ``source_path`` and ``images`` locate the images when ``--images`` is not given) and
``point_cloud/iteration_N/point_cloud.ply`` (the newest ``N`` unless ``iteration`` is given).
The trainer also copies its initial sparse points there as ``input.ply``; the ground plane is
fitted to those when present (SfM points lie on the surfaces; trained splat centres scatter
a few centimetres about them, which at a camera height of 1.6 m is a scale error of percents).
"""

from __future__ import annotations

import ast
import json
import re
from pathlib import Path

import numpy as np

from .. import conventions
from ..errors import InputError
from .frames import DEFAULT_CAMERA, DEFAULT_FPS, View, group_views, named_file
from .package import Source

IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".JPG", ".JPEG", ".PNG", ".exr", ".tif", ".tiff")


def read_cfg_args(path: Path) -> dict:
    """Keyword arguments of the ``Namespace(...)`` repr in ``cfg_args`` (literals only)."""
    try:
        text = path.read_text(encoding="utf-8-sig")
        node = ast.parse(text.strip(), mode="eval").body
    except (OSError, UnicodeDecodeError, SyntaxError, ValueError):
        raise InputError(path, "not a Namespace(...) of the 3DGS trainer's arguments", "cfg_args") from None
    if not isinstance(node, ast.Call):
        raise InputError(path, "not a Namespace(...) of the 3DGS trainer's arguments", "cfg_args")
    out = {}
    for kw in node.keywords:
        try:
            out[kw.arg] = ast.literal_eval(kw.value)
        except ValueError:
            pass
    return out


def newest_iteration(model: Path, iteration: int | None) -> Path:
    pc = model / "point_cloud"
    its = {}
    if pc.is_dir():
        for d in pc.iterdir():
            m = re.fullmatch(r"iteration_(\d+)", d.name)
            if m and (d / "point_cloud.ply").is_file():
                its[int(m.group(1))] = d / "point_cloud.ply"
    if iteration is not None:
        if iteration not in its:
            have = ", ".join(map(str, sorted(its))) or "none"
            raise InputError(pc / f"iteration_{iteration}" / "point_cloud.ply", f"not found (iterations: {have})",
                             "--iteration")
        return its[iteration]
    if not its:
        raise InputError(pc, "no iteration_*/point_cloud.ply (is this a 3DGS trainer output folder?)", "point_cloud")
    return its[max(its)]


def _find_image(folder: Path, stem: str) -> Path:
    if (folder / stem).is_file():
        return folder / stem
    for ext in IMAGE_EXTENSIONS:
        if (folder / (stem + ext)).is_file():
            return folder / (stem + ext)
    return folder / (stem + ".png")  # reported as missing by the package writer


def read_views(model: str | Path, images: str | Path | None) -> list[View]:
    """The views of ``cameras.json`` in the trainer's output folder ``model`` (images looked up in
    ``images``, else where ``cfg_args`` says): poses and intrinsics only, no splats read."""
    model = Path(model)
    cams_path = model / "cameras.json"
    if not cams_path.is_file():
        raise InputError(cams_path, "file not found (expected the 3DGS trainer's output folder)", "cameras.json")
    try:
        cams = json.loads(cams_path.read_text(encoding="utf-8-sig"))
    except (UnicodeDecodeError, RecursionError, ValueError) as exc:  # ValueError: JSON's, a number of thousands of digits
        raise InputError(cams_path, f"not valid JSON: {exc}") from None
    if not isinstance(cams, list):
        raise InputError(cams_path, "expected a list of cameras", "(root)")
    if not cams:
        raise InputError(cams_path, "empty: no cameras", "(root)")
    if images is None:
        cfg = read_cfg_args(model / "cfg_args") if (model / "cfg_args").is_file() else {}
        if "source_path" not in cfg:
            raise InputError(model / "cfg_args", "no source_path to find the images in; pass --images DIR",
                             "source_path")
        for key, value in (("source_path", cfg["source_path"]), ("images", cfg.get("images", "images"))):
            if not isinstance(value, str) or not value:
                raise InputError(model / "cfg_args", f"expected a folder's path, got {value!r}", key)
        images = Path(cfg["source_path"]) / cfg.get("images", "images")
    images = Path(images)
    views = []
    for i, c in enumerate(cams):
        where = f"[{i}]"
        if not isinstance(c, dict):
            raise InputError(cams_path, "expected an object", where)
        for key in ("img_name", "width", "height", "position", "rotation", "fx", "fy"):
            if key not in c:
                raise InputError(cams_path, "required field is missing", f"{where}.{key}")
        try:
            pos = np.asarray(c["position"], dtype=np.float64).reshape(3)
            rot = np.asarray(c["rotation"], dtype=np.float64).reshape(3, 3)
            fx, fy, w, h = float(c["fx"]), float(c["fy"]), int(c["width"]), int(c["height"])
        except (TypeError, ValueError, OverflowError):
            raise InputError(cams_path, "expected position [3], rotation [3][3], numeric fx, fy, width, height",
                             where) from None
        c2w = np.eye(4)
        c2w[:3, :3], c2w[:3, 3] = rot, pos
        if not np.all(np.isfinite(c2w)):
            raise InputError(cams_path, "pose is not finite (NaN or Inf)", f"{where}.position")
        name = str(c["img_name"])
        named_file(images, name, cams_path, f"{where}.img_name")
        image = _find_image(images, name)
        views.append(View(name=image.name if image.is_file() else name, K=conventions.intrinsics(fx, fy, w / 2.0, h / 2.0),
                          width=w, height=h, c2w=c2w, source=cams_path, where=f"{where} ({name})", image=image,
                          camera_id="0"))
    return views


def read_gs_output(model: str | Path, images: str | Path | None, *, iteration: int | None = None,
                   splats: str | Path | None = None, camera_name: str = DEFAULT_CAMERA, fps: float = DEFAULT_FPS) -> Source:
    model = Path(model)
    views = read_views(model, images)
    ply = Path(splats) if splats is not None else newest_iteration(model, iteration)
    from ..io.ply import read_splats

    g = read_splats(ply)
    points = colors = None
    if (model / "input.ply").is_file():
        from ..io.points import read_points

        p, c = read_points(model / "input.ply")
        points, colors = p.astype(np.float64), c.astype(np.float64)
    return Source("3dgs", model, group_views(views, camera_name=camera_name, fps=fps), splats=g, splats_path=ply,
                  points=points, colors=colors, notes={"splats_file": str(ply)})
