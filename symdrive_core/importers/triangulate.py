"""Points for a drive that has poses and images but no points (a nerfstudio ``transforms.json``
without ``ply_file_path``, a COLMAP model without ``points3D``): COLMAP's SIFT features, matched
between neighbouring frames, triangulated with the recorded poses and intrinsics held fixed
(``pycolmap.triangulate_points``, what ``colmap point_triangulator`` runs: its bundle adjustment
moves the points only).

The points are what the ground fit needs and what ``symdrive reconstruct`` starts its Gaussians
from, so a poses-only drive imports, reconstructs and runs like any other. The work happens in
a temporary folder beside the package (images linked in under names the importer makes, never
names from the source), removed whether it succeeds or not.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import conventions
from ..errors import InputError
from ..io import link_or_copy
from .colmap import load_pycolmap
from .frames import Grouped


@dataclass(frozen=True)
class TriangulateConfig:
    max_image_size: int = 1600  # SIFT on images downscaled to this (pixels, longer side)
    max_features: int = 8192  # per image
    overlap: int = 10  # each frame is matched with the next this many (quadratically spaced beyond)
    threads: int = 4  # SIFT extraction threads (each holds a copy of the image pyramid)


DEFAULT = TriangulateConfig()


@dataclass
class Triangulated:
    points: np.ndarray  # [N, 3] source frame
    colors: np.ndarray  # [N, 3] in [0, 1]
    record: dict  # for the manifest's source block


def _layout(grouped: Grouped, folder: Path, frames: list[int]) -> dict[str, tuple]:
    """Link the images of ``frames`` in as ``{frame:06d}/{camera}{ext}``: sorted by name, a frame's
    cameras sit together and the sequential matcher pairs them as well as neighbouring frames."""
    names = {}
    for cam, row in zip(grouped.cameras, grouped.table):
        for fi in frames:
            v = row[fi]
            name = f"{fi:06d}/{cam}{v.image.suffix.lower()}"
            link_or_copy(v.image, folder / name)
            names[name] = (v, np.asarray(v.K, dtype=np.float64))
    return names


def triangulate(grouped: Grouped, near: Path, cfg: TriangulateConfig = DEFAULT,
                frames: list[int] | None = None) -> Triangulated:
    """Triangulate points from the images of ``grouped``'s ``frames`` (default: all) with its poses
    fixed; work beside ``near``."""
    pycolmap = load_pycolmap()
    near = Path(near)
    near.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{near.name}.triangulate.", suffix=".part", dir=near.parent))
    level = pycolmap.logging.minloglevel
    # per-image progress and bundle adjustment's warnings (a gauge it cannot fix when nothing
    # matched) are noise here: the import says how many points came and how well they fit
    pycolmap.logging.minloglevel = int(pycolmap.logging.Level.ERROR)
    try:
        names = _layout(grouped, tmp / "images", list(range(len(grouped.frame_keys))) if frames is None else frames)
        db = tmp / "database.db"
        extraction = pycolmap.FeatureExtractionOptions()
        extraction.max_image_size = cfg.max_image_size
        extraction.num_threads = min(cfg.threads, os.cpu_count() or 1)
        extraction.sift.max_num_features = cfg.max_features
        pairing = pycolmap.SequentialPairingOptions()
        pairing.overlap = cfg.overlap * len(grouped.cameras)
        try:
            pycolmap.extract_features(db, tmp / "images", image_names=sorted(names),
                                      camera_mode=pycolmap.CameraMode.PER_IMAGE, extraction_options=extraction,
                                      device=pycolmap.Device.cpu)
            pycolmap.match_sequential(db, pairing_options=pairing, device=pycolmap.Device.cpu)
            rec = pycolmap.Reconstruction()
            database = pycolmap.Database.open(str(db))
            try:
                for im in database.read_all_images():
                    v, K = names[im.name]
                    cam = pycolmap.Camera(camera_id=im.camera_id, model="PINHOLE", width=v.width, height=v.height,
                                          params=[K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
                    database.update_camera(cam)
                    rec.add_camera_with_trivial_rig(cam)
                    w2c = conventions.invert_rigid(v.c2w)
                    rec.add_image_with_trivial_frame(pycolmap.Image(image_id=im.image_id, name=im.name,
                                                                    camera_id=im.camera_id),
                                                     pycolmap.Rigid3d(w2c[:3, :4]))
            finally:
                database.close()
            (tmp / "sparse").mkdir()
            rec = pycolmap.triangulate_points(rec, db, tmp / "images", tmp / "sparse")
        except Exception as exc:  # pycolmap raises plain RuntimeError/ValueError
            v = grouped.table[0][0]
            raise InputError(v.source, f"cannot triangulate points from the images: {' '.join(str(exc).split())[:300]}",
                             "images") from None
        pts = list(rec.points3D.values())
        points = np.array([p.xyz for p in pts], dtype=np.float64).reshape(-1, 3)
        colors = np.array([p.color for p in pts], dtype=np.float64).reshape(-1, 3) / 255.0
        errors = np.array([p.error for p in pts], dtype=np.float64)
        record = {"points": len(pts), "images": len(names),
                  "mean_track_length": float(np.mean([p.track.length() for p in pts])) if pts else 0.0,
                  "mean_reprojection_error_px": float(errors.mean()) if len(errors) else 0.0}
        return Triangulated(points, colors, record)
    finally:
        pycolmap.logging.minloglevel = level
        shutil.rmtree(tmp, ignore_errors=True)
