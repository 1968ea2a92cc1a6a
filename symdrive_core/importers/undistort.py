"""COLMAP models with lens distortion, undistorted by COLMAP's own undistorter
(``pycolmap.undistort_images``) so the importer sees PINHOLE cameras and the images that match them.

The undistorter writes a PINHOLE model and resampled images (their size and focal length chosen by
COLMAP so that no blank pixels show) into a temporary folder beside the package; the importer
copies the images into the package and the folder is removed, whether the import succeeds or not.
Poses do not change: undistortion only resamples the images.
"""

from __future__ import annotations

import contextlib
import shutil
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from .colmap import load_pycolmap, model_file, model_name, pinhole_K, read_model
from .package import check_image


@dataclass
class Undistorted:
    """Where the PINHOLE model and its images are, and the original cameras (for the manifest)."""

    model: Path
    images: Path
    cameras: dict = field(default_factory=dict)  # camera id -> {"model", "width", "height", "params"}


def distorted_cameras(rec) -> dict:
    return {str(cid): {"model": model_name(cam), "width": int(cam.width), "height": int(cam.height),
                       "params": np.asarray(cam.params, dtype=np.float64).tolist()}
            for cid, cam in sorted(rec.cameras.items()) if pinhole_K(cam) is None}


def _posed(rec):
    return [(iid, im) for iid, im in sorted(rec.images.items()) if getattr(im, "has_pose", True)]


def _check_inputs(rec, model_dir: Path, images: Path) -> None:
    """Every registered image is there at its camera's size: the undistorter only logs a missing one."""
    img_file = model_file(model_dir, "images")
    for iid, im in _posed(rec):
        cam = rec.cameras[im.camera_id]
        check_image(images / im.name, int(cam.width), int(cam.height), img_file, f"image_id {iid} ({im.name})")


@contextlib.contextmanager
def undistorted(model_dir: str | Path, images: str | Path | None, out: str | Path) -> Iterator[Undistorted | None]:
    """Yield the undistorted model beside ``out`` (None when no camera has lens distortion)."""
    model_dir, out = Path(model_dir), Path(out)
    rec = read_model(model_dir)
    cameras = distorted_cameras(rec)
    if not cameras:
        yield None
        return
    if images is None:
        raise InputError("--images", "--undistort needs the recorded images: pass --images DIR")
    images = Path(images)
    _check_inputs(rec, model_dir, images)
    pycolmap = load_pycolmap()
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.undistort.", suffix=".part", dir=out.parent))
    try:
        level = pycolmap.logging.minloglevel
        pycolmap.logging.minloglevel = int(pycolmap.logging.Level.WARNING)  # its per-image progress is noise here
        try:
            pycolmap.undistort_images(str(tmp), str(model_dir), str(images))
        except Exception as exc:  # pycolmap raises plain RuntimeError/ValueError
            raise InputError(model_dir, f"COLMAP's undistorter failed: {' '.join(str(exc).split())[:300]}",
                             "model") from None
        finally:
            pycolmap.logging.minloglevel = level
        for iid, im in _posed(rec):
            if not (tmp / "images" / im.name).is_file():
                raise InputError(images / im.name, "COLMAP's undistorter wrote no undistorted image for it",
                                 f"image_id {iid}")
        yield Undistorted(tmp / "sparse", tmp / "images", cameras)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
