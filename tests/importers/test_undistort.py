"""Lens-distorted COLMAP cameras (OPENCV) come in through COLMAP's undistorter: PINHOLE cameras,
images where straight lines are straight and every point sits within a pixel of where the new K
puts it, the same poses as a pinhole import, and nothing left behind on success or failure."""

from __future__ import annotations

import time

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.importers.colmap import load_pycolmap, model_name, pinhole_K
from symdrive_core.importers.undistort import undistorted
from symdrive_core.io.images import read_image, write_image
from symdrive_core.metrics import psnr
from symdrive_core.scene import check_files, load_manifest

from .demo_formats import CAMERA_HEIGHT, World, demo_world, write_colmap
from .lens import bilinear, distort, distort_image, ideal_coords
from .test_bad_input import assert_refused
from .test_roundtrip import roundtrip_errors

pytest.importorskip("pycolmap")

COEFFS = (-0.18, 0.03, 0.002, -0.001)  # k1, k2, p1, p2: about 6 px of barrel at the edges
W, H = 240, 160
DOT_PARAMS = (150.0, 152.0, 121.0, 79.0, *COEFFS)
ROWS = np.linspace(-0.4, 0.4, 5)
COLS = np.linspace(-0.7, 0.7, 9)
SIGMA = 0.01  # dot radius in normalised units (1.5 px)


def _dots(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return sum(np.exp(-((x - gx) ** 2 + (y - gy) ** 2) / (2 * SIGMA**2)) for gy in ROWS for gx in COLS)


def _centroid(img: np.ndarray, u: float, v: float, r: int = 5) -> np.ndarray | None:
    """Intensity centroid of the dot near (u, v), continuous pixel coordinates; None near the edge."""
    j0, i0 = int(u) - r, int(v) - r
    if j0 < 0 or i0 < 0 or j0 + 2 * r + 1 > img.shape[1] or i0 + 2 * r + 1 > img.shape[0]:
        return None
    win = img[i0:i0 + 2 * r + 1, j0:j0 + 2 * r + 1]
    w = np.clip(win - 0.05, 0, None)
    jj, ii = np.meshgrid(np.arange(j0, j0 + 2 * r + 1) + 0.5, np.arange(i0, i0 + 2 * r + 1) + 0.5)
    return np.array([(w * jj).sum(), (w * ii).sum()]) / w.sum()


def _bow(points: np.ndarray) -> float:
    """Largest distance (px) of points from their least-squares line."""
    c = points - points.mean(0)
    return float(np.abs(c @ np.linalg.svd(c)[2][1]).max())


def _one_view_model(root, params, image_name="dots.png"):
    world = World(S=np.eye(4), names=[image_name], images=[], K=np.eye(3), width=W, height=H, c2w=np.eye(4)[None],
                  c2w_demo=np.eye(4)[None], splats=None, points=np.zeros((0, 3)), colors=np.zeros((0, 3)))
    return write_colmap(world, root / "sparse", model_name="OPENCV", params=list(params), with_points=False)


def test_undistorted_dots_sit_where_the_pinhole_K_puts_them_and_rows_are_straight(tmp_path):
    x, y = ideal_coords(W, H, DOT_PARAMS)
    distorted = _dots(x, y)
    write_image(tmp_path / "images" / "dots.png", np.repeat(distorted[..., None], 3, axis=2).astype(np.float32))
    model = _one_view_model(tmp_path, DOT_PARAMS)
    out = tmp_path / "pkg"
    with undistorted(model, tmp_path / "images", out) as und:
        assert und.cameras == {"1": {"model": "OPENCV", "width": W, "height": H, "params": list(DOT_PARAMS)}}
        cam = load_pycolmap().Reconstruction(str(und.model)).cameras[1]
        assert model_name(cam) == "PINHOLE"
        K = pinhole_K(cam)
        img = read_image(und.images / "dots.png")[..., 0].astype(np.float64)
    assert not list(tmp_path.glob(".pkg.*")), "the undistorter's folder is removed"
    errors, rows_after, rows_before = [], [], []
    for gy in ROWS:
        after, before = [], []
        for gx in COLS:
            expected = np.array([K[0, 0] * gx + K[0, 2], K[1, 1] * gy + K[1, 2]])
            got = _centroid(img, *expected)
            xd, yd = distort(np.array(gx), np.array(gy), *COEFFS)
            seen = _centroid(distorted, DOT_PARAMS[0] * xd + DOT_PARAMS[2], DOT_PARAMS[1] * yd + DOT_PARAMS[3])
            if got is not None and seen is not None:
                errors.append(np.linalg.norm(got - expected))
                after.append(got)
                before.append(seen)
        if len(after) >= 5:
            rows_after.append(_bow(np.array(after)))
            rows_before.append(_bow(np.array(before)))
    assert len(errors) >= 30, len(errors)
    assert max(errors) < 1.0, max(errors)  # within a pixel of the pinhole projection
    assert len(rows_after) >= 4
    print(f"dots: {len(errors)}, max error {max(errors):.3f} px, bow {max(rows_before):.2f} -> {max(rows_after):.3f} px")
    assert max(rows_before) > 2.0, rows_before  # the recorded rows really bend
    assert max(rows_after) < 0.5, rows_after  # and come out straight


@pytest.fixture(scope="module")
def world():
    return demo_world(seed=5, max_splats=4000)


def _distorted_demo(world, root):
    """The demo street as an OPENCV camera with the demo's K plus lens distortion saw it."""
    params = [world.K[0, 0], world.K[1, 1], world.K[0, 2], world.K[1, 2], *COEFFS]
    for name, src in zip(world.names, world.images):
        write_image(root / "images" / name, distort_image(read_image(src, channels=3), world.K, params)
                    .astype(np.float32))
    return write_colmap(world, root / "sparse", model_name="OPENCV", params=params), params


def test_import_with_undistort_gives_pinhole_cameras_the_same_poses_and_matching_images(world, tmp_path, capsys):
    model, params = _distorted_demo(world, tmp_path)
    out = tmp_path / "pkg"
    t0 = time.perf_counter()
    rc = main(["import", "colmap", str(model), "--images", str(tmp_path / "images"), "--out", str(out),
               "--camera-height", str(CAMERA_HEIGHT), "--undistort"])
    seconds = time.perf_counter() - t0
    printed = capsys.readouterr()
    assert rc == 0, printed.err
    assert "undistorted 30 images of camera 1 (OPENCV) to PINHOLE" in printed.out
    print(f"import colmap --undistort, 30 frames of {world.width}x{world.height}: {seconds:.2f} s")
    m = load_manifest(out)  # images copied in: no external assets
    check_files(m)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".pkg.")]
    assert m.source["undistorted_cameras"]["1"]["params"] == params
    assert m.source["path"] == str(model)
    pos_err, ang_err = roundtrip_errors(out, world)
    assert pos_err < 0.02 and ang_err < 0.1, (pos_err, ang_err)
    cam = m.cameras[0]
    K = cam.frames[0].K
    assert K[0, 1] == 0 and all(np.array_equal(f.K, K) for f in cam.frames)
    # each undistorted image is the original (pinhole) demo view seen through the new K
    u, v = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    x, y = (u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1]
    for fi in (0, 17):
        assert cam.frames[fi].image == f"images/front/{fi:06d}.png"
        got = read_image(m.resolve(cam.frames[fi].image), channels=3)
        expected = bilinear(read_image(world.images[fi], channels=3), world.K[0, 0] * x + world.K[0, 2],
                            world.K[1, 1] * y + world.K[1, 2])
        as_recorded = bilinear(read_image(tmp_path / "images" / world.names[fi], channels=3),
                               u * world.width / cam.width, v * world.height / cam.height)
        print(f"frame {fi}: PSNR {psnr(got, expected):.1f} dB against the pinhole view "
              f"(the distorted image resized: {psnr(as_recorded, expected):.1f} dB)")
        assert psnr(got, expected) > 33.0
        assert psnr(got, expected) > psnr(as_recorded, expected) + 10.0


def test_a_distorted_camera_without_undistort_is_refused_naming_the_flag(world, tmp_path, capsys):
    model, _ = _distorted_demo(world, tmp_path)
    out = tmp_path / "pkg"
    rc = main(["import", "colmap", str(model), "--images", str(tmp_path / "images"), "--out", str(out),
               "--camera-height", str(CAMERA_HEIGHT)])
    assert_refused(rc, capsys.readouterr().err.strip(), out, "camera_id 1", "OPENCV", "--undistort")


def test_undistort_with_a_missing_image_writes_nothing(world, tmp_path, capsys):
    model, _ = _distorted_demo(world, tmp_path)
    (tmp_path / "images" / "000007.png").unlink()
    out = tmp_path / "pkg"
    rc = main(["import", "colmap", str(model), "--images", str(tmp_path / "images"), "--out", str(out),
               "--camera-height", str(CAMERA_HEIGHT), "--undistort"])
    assert_refused(rc, capsys.readouterr().err.strip(), out, "000007.png", "image_id 8", "not found")
