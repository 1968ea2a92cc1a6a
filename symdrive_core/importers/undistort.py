"""COLMAP models with lens distortion, undistorted by COLMAP's own undistorter
(``pycolmap.undistort_images``) so the importer sees PINHOLE cameras and the images that match them.
Views of other formats with a lens (nerfstudio's OPENCV, OPENCV_FISHEYE) go through the same
undistorter as a COLMAP model written for them (:func:`undistorted_views`).

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
from ..io import link_or_copy
from .colmap import load_pycolmap, model_file, model_name, pinhole_K, read_model
from .frames import View
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


def _lens_model(views: list[View], folder: Path) -> None:
    """A COLMAP model of ``views`` (each with a ``lens``) at ``folder/sparse``, their images linked
    into ``folder/images`` as ``{n:06d}.ext`` (image n+1 of the model)."""
    pycolmap = load_pycolmap()
    rec = pycolmap.Reconstruction()
    cameras: dict = {}
    for n, v in enumerate(views):
        check_image(v.image, v.width, v.height, v.source, v.where)
        key = (v.lens[0], tuple(v.lens[1]), v.width, v.height)
        if key not in cameras:
            cameras[key] = len(cameras) + 1
            rec.add_camera_with_trivial_rig(pycolmap.Camera(camera_id=cameras[key], model=v.lens[0], width=v.width,
                                                            height=v.height, params=list(v.lens[1])))
        name = f"{n:06d}{v.image.suffix.lower()}"
        link_or_copy(v.image, folder / "images" / name)
        w2c = np.linalg.inv(v.c2w)
        rec.add_image_with_trivial_frame(pycolmap.Image(image_id=n + 1, name=name, camera_id=cameras[key]),
                                         pycolmap.Rigid3d(w2c[:3, :4]))
    (folder / "sparse").mkdir(parents=True)
    rec.write_text(str(folder / "sparse"))


@contextlib.contextmanager
def undistorted_views(views: list[View], out: str | Path) -> Iterator[dict | None]:
    """Give the views with a ``lens`` the PINHOLE K, size and image COLMAP's undistorter makes of
    them (in place; their poses stay) and yield the original cameras by the lens' camera id, as
    :func:`undistorted` records them; None when no view has a lens. The images live beside
    ``out`` until the context ends."""
    lensed = [v for v in views if v.lens is not None]
    if not lensed:
        yield None
        return
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.lens.", suffix=".part", dir=out.parent))
    try:
        _lens_model(lensed, tmp)
        with undistorted(tmp / "sparse", tmp / "images", out) as und:
            rec = read_model(und.model)
            for iid, im in rec.images.items():
                v, cam = lensed[iid - 1], rec.cameras[im.camera_id]
                v.K, v.width, v.height, v.image, v.lens = pinhole_K(cam), int(cam.width), int(cam.height), \
                    und.images / im.name, None
            yield und.cameras
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
