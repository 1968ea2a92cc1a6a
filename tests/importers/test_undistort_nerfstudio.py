"""nerfstudio cameras with lens distortion come in through the same undistorter as COLMAP models
(``import nerfstudio --undistort``): the same PINHOLE K and the same pixels as
``import colmap --undistort`` of the same drive, the demo's poses, the original lens recorded,
nothing left behind; without the flag the lens is refused naming it."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.importers.nerfstudio import colmap_lens
from symdrive_core.io.images import read_image
from symdrive_core.scene import check_files, load_manifest

from .demo_formats import CAMERA_HEIGHT, demo_world, write_nerfstudio
from .test_bad_input import assert_refused
from .test_roundtrip import roundtrip_errors
from .test_undistort import COEFFS, _distorted_demo

pytest.importorskip("pycolmap")


@pytest.fixture(scope="module")
def world():
    return demo_world(seed=6, max_splats=4000)


def _distorted_nerfstudio(world, root: Path) -> tuple[Path, Path]:
    """(COLMAP model, transforms.json) of the same distorted images, OPENCV lens k1, k2, p1, p2."""
    model, _ = _distorted_demo(world, root)
    distorted = replace(world, images=[root / "images" / n for n in world.names])
    tj = write_nerfstudio(distorted, root / "ns")
    data = json.loads(tj.read_text())
    data.update(zip(("k1", "k2", "p1", "p2"), COEFFS))
    tj.write_text(json.dumps(data))
    return model, tj


def test_nerfstudio_undistort_gives_what_colmap_undistort_gives(world, tmp_path, capsys):
    model, tj = _distorted_nerfstudio(world, tmp_path)
    ns_out, colmap_out = tmp_path / "ns_pkg", tmp_path / "colmap_pkg"
    rc = main(["import", "nerfstudio", str(tj), "--out", str(ns_out), "--camera-height", str(CAMERA_HEIGHT),
               "--undistort", "--quiet"])
    printed = capsys.readouterr()
    assert rc == 0, printed.err
    assert "undistorted 30 images of camera 1 (OPENCV) to PINHOLE" in printed.out
    rc = main(["import", "colmap", str(model), "--images", str(tmp_path / "images"), "--out", str(colmap_out),
               "--camera-height", str(CAMERA_HEIGHT), "--undistort", "--quiet"])
    assert rc == 0, capsys.readouterr().err
    ns, colmap = load_manifest(ns_out), load_manifest(colmap_out)  # images copied in: no external assets
    check_files(ns)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".ns_pkg.")]
    lens = ns.source["undistorted_cameras"]["1"]
    assert lens["model"] == "OPENCV" and np.allclose(lens["params"][4:], COEFFS)
    pos_err, ang_err = roundtrip_errors(ns_out, world)
    assert pos_err < 0.02 and ang_err < 0.1, (pos_err, ang_err)
    a, b = ns.cameras[0], colmap.cameras[0]
    assert (a.width, a.height) == (b.width, b.height)
    assert np.allclose(a.frames[0].K, b.frames[0].K, rtol=1e-9)
    assert not np.allclose(a.frames[0].K, world.K)  # COLMAP chose a new K: the images were resampled
    for fi in (0, 13, 29):
        assert np.array_equal(read_image(ns.resolve(a.frames[fi].image)), read_image(colmap.resolve(b.frames[fi].image)))


def test_nerfstudio_lens_without_undistort_is_refused_naming_the_flag(world, tmp_path, capsys):
    _, tj = _distorted_nerfstudio(world, tmp_path)
    out = tmp_path / "pkg"
    rc = main(["import", "nerfstudio", str(tj), "--out", str(out), "--camera-height", str(CAMERA_HEIGHT)])
    assert_refused(rc, capsys.readouterr().err.strip(), out, "transforms.json", "k1", "--undistort")


@pytest.mark.parametrize("model, coeffs, expected", [
    ("OPENCV", {"k1": 0.1, "k2": -0.02, "p1": 1e-3, "p2": -2e-3}, ("OPENCV", [0.1, -0.02, 1e-3, -2e-3])),
    ("OPENCV", {"k1": 0.1, "k3": 0.01}, ("FULL_OPENCV", [0.1, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0])),
    ("OPENCV_FISHEYE", {"k1": 0.05, "k4": -0.001}, ("OPENCV_FISHEYE", [0.05, 0.0, 0.0, -0.001])),
])
def test_nerfstudio_lenses_map_to_colmap_models_with_the_same_coefficients(model, coeffs, expected):
    intr = {"fl_x": 500.0, "fl_y": 502.0, "cx": 320.0, "cy": 240.0, "k1": None, "k2": None, "k3": None, "k4": None,
            "p1": None, "p2": None, **coeffs}
    name, params = colmap_lens(model, intr, Path("transforms.json"), "frames[0]")
    assert (name, params[4:]) == expected
    assert params[:4] == [500.0, 502.0, 320.0, 240.0]
