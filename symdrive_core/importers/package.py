"""Write an imported scene package atomically: checked inputs, a temporary folder beside the
target, the core's own validation, then one rename. Bad input leaves nothing behind."""

from __future__ import annotations

import os
import shutil
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import conventions
from ..errors import InputError
from ..gaussians import Gaussians
from ..io import link_or_copy
from ..scene import is_inside
from .frames import Grouped, split_heldout
from .ground import align
from .similarity import apply_camera, apply_points, transform_gaussians
from .stereo import StereoTruth, lateral_entry


@dataclass
class Source:
    """What an importer read: views plus the reconstruction's geometry, in the source frame."""

    format: str
    path: Path
    grouped: Grouped
    splats: Gaussians | None = None
    splats_path: Path | None = None
    points: np.ndarray | None = None  # [N, 3] sparse points
    colors: np.ndarray | None = None  # [N, 3] in [0, 1]
    # [N] the frame each point was seen in (a LiDAR's returns), so a held-out frame's can be left
    # out, -1 for points joined from no one frame; None: no frame's points (triangulated, a model's)
    point_frames: np.ndarray | None = None
    # Maps the original reconstruction's frame to the frame the poses are written in (nerfstudio's
    # applied_transform); None: the same frame.
    pre: np.ndarray | None = None
    notes: dict = field(default_factory=dict)
    lateral: StereoTruth | None = None  # a rig's second camera, written as lateral ground truth


@dataclass
class Options:
    out: Path
    camera_height: float | None = None
    scale: float | None = None
    up: tuple[float, float, float] | None = None
    heldout_every: int | None = None
    copy_images: bool = False
    force: bool = False
    name: str | None = None


def parse_up(text: str | None):
    if text is None:
        return None
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 3 or not np.all(np.isfinite(v)) or np.linalg.norm(v) == 0:
        raise InputError("--up", f"expected three numbers x,y,z (not all zero), got {text!r}")
    return tuple(v)


def check_image(image: Path, width: int, height: int, source: Path, where: str) -> None:
    """A recorded image exists and has its camera's size (``source``/``where`` name the record)."""
    from ..io.images import image_size

    if not image.is_file():
        raise InputError(image, f"image not found (named by {source.name})", where)
    w, h, _ = image_size(image, where)
    if (w, h) != (width, height):
        raise InputError(image, f"image is {w}x{h}, the camera ({source}: {where}) is {width}x{height}", where)


def _check_images(g: Grouped, lateral: StereoTruth | None) -> None:
    for row in g.table + ([] if lateral is None else [lateral.views]):
        for v in row:
            if v.image is not None:
                check_image(v.image, v.width, v.height, v.source, v.where)


@contextmanager
def _named_by_source(tmp: Path, source: Path):
    """An error in the package being written (a value the source holds that no package may) named by
    the source it came from: the temporary folder is gone when the user reads the message."""
    try:
        yield
    except InputError as exc:
        inside = Path(exc.path).resolve()
        if not inside.is_relative_to(tmp.resolve()):
            raise
        field = exc.field or inside.relative_to(tmp.resolve()).as_posix()
        raise InputError(source, f"{exc.message} (in the scene package made from this input)", field) from None


def write_package(src: Source, opt: Options, progress: bool = True, extend=None) -> dict:
    """Align ``src`` to a metric Z-up world and write it as a package at ``opt.out``; returns a
    summary (frames, cameras, transform, the ground fit's quality, whether the package reads files
    outside itself). ``progress`` shows a bar over the images (copying thousands takes a while).
    ``extend(folder)``, when given, adds to the package written in ``folder`` (a drive's LiDAR depth
    and tracked vehicles) before it is validated and renamed into place, so they land with the
    package or not at all; what it returns is the summary's ``extended``."""
    from tqdm import tqdm

    from ..io.atomic import atomic_directory
    from ..io.ply import write_splats
    from ..io.points import write_points
    from ..scene.manifest import check_files, load_manifest, parse_manifest

    out = Path(opt.out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        if not (out / "manifest.json").is_file():  # somebody's folder: never replaced, --force or not
            raise InputError(out, "exists, is not empty and is not a scene package; choose another folder", "--out")
        if not opt.force:
            raise InputError(out, "a scene package is already there; pass --force to replace it", "--out")
    g = src.grouped
    _check_images(g, src.lateral)
    c2ws = np.stack([np.stack([v.c2w for v in row]) for row in g.table])  # [camera, frame, 4, 4]
    pts = None
    if src.points is not None and len(src.points):
        pts = src.points if src.point_frames is None else src.points[src.point_frames >= 0]  # the returns alone
    elif src.splats is not None and len(src.splats):
        pts = src.splats.means
    T, record = align(pts, c2ws, camera_height=opt.camera_height, scale=opt.scale, up=opt.up)
    name = opt.name or out.resolve().name
    external = False
    n_images = sum(len(row) for row in g.table) + (0 if src.lateral is None else len(src.lateral.views))
    bar = tqdm(total=n_images, desc="import", unit="image", disable=not progress)
    with atomic_directory(out) as tmp, bar:
        def place(image: Path, copy_as: str) -> str:
            """The package's path of a recorded image: copied to ``copy_as``, linked when it is
            inside the package already, else referenced relative to the package."""
            nonlocal external
            bar.update()
            if opt.copy_images:
                dst = tmp / copy_as
                dst.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(image, dst)
                return copy_as
            if is_inside(image, out):
                rel = image.resolve().relative_to(out.resolve()).as_posix()
                link_or_copy(image, tmp / rel)
                return rel
            external = True
            return Path(os.path.relpath(image.resolve(), out.resolve())).as_posix()

        cams = []
        for cam, row in zip(g.cameras, g.table):
            frames = []
            for fi, v in enumerate(row):
                c2w = apply_camera(T, v.c2w)
                entry = {"K": v.K.tolist(), "camera_to_world": c2w.tolist(),
                         "world_to_camera": conventions.invert_rigid(c2w).tolist()}
                if v.image is None:
                    bar.update()
                else:
                    entry["image"] = place(v.image, f"images/{cam}/{fi:06d}{v.image.suffix.lower()}")
                frames.append(entry)
            cams.append({"name": cam, "width": row[0].width, "height": row[0].height, "frames": frames})
        background = {}
        if src.splats is not None:
            write_splats(tmp / "reconstruction" / "background.ply", transform_gaussians(src.splats, T))
            background["splats"] = "reconstruction/background.ply"
        if src.points is not None and len(src.points):
            colors = src.colors if src.colors is not None else np.full((len(src.points), 3), 0.5)
            write_points(tmp / "background" / "points.ply", apply_points(T, src.points), colors)
            background["points"] = "background/points.ply"
        train, held = split_heldout(len(g.frame_keys), opt.heldout_every)
        data = {
            "format": "symdrive-scene", "version": 1, "name": name,
            "frames": [{"index": i, "timestamp": t} for i, t in enumerate(g.timestamps)],
            "cameras": cams, "background": background, "actors": [],
            "source": {"format": src.format, "path": str(src.path),
                       "transform": (T if src.pre is None else T @ src.pre).tolist(),
                       **({} if src.pre is None else {"poses_transform": T.tolist()}),
                       "frame_names": list(g.frame_keys), **record, **src.notes},
            "ground_truth": {"camera": g.cameras[0], "train_frames": train, "heldout_frames": held},
        }
        if src.lateral is not None:
            entry = lateral_entry(src.lateral, record["scale"], place)
            data["ground_truth"]["lateral"] = [entry]
            data["effects"] = {"lateral_offsets": [entry["offset_m"]]}
            data["source"]["stereo"] = {"camera": src.lateral.name, "baseline_source_units": src.lateral.baseline}
        with _named_by_source(tmp, src.path):
            m = parse_manifest(data, tmp / "manifest.json", allow_external=external)
            m.save()
            extended = None if extend is None else extend(tmp)
            m = load_manifest(tmp, allow_external=external)
            check_files(m)
    return {"package": str(out), "frames": len(g.frame_keys), "cameras": g.cameras,
            "lateral_offset_m": None if src.lateral is None else data["effects"]["lateral_offsets"][0],
            "scale": record["scale"], "camera_height_m": record["camera_height_m"],
            "ground_fit": record["ground_fit"], "external_images": external, "transform": T,
            "extended": extended}
