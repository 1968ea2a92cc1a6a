"""LiDAR import against a synthetic scan of the demo street: points back-projected from its dense
Cycles depth at a sparse set of pixels, moved into a KITTI-like sensor frame, written as scans;
the imported sparse depth must give back that depth at those pixels and nothing elsewhere."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from symdrive_core import conventions
from symdrive_core.cli import main
from symdrive_core.errors import InputError
from symdrive_core.importers.lidar import read_scan, read_sensor_to_camera, sparse_depth
from symdrive_core.io.images import read_image
from symdrive_core.io.points import write_points
from symdrive_core.rotations import quat_to_matrix
from symdrive_core.scene import load_manifest
from symdrive_core.scene.depth import read_depth
from tests.importers.demo_formats import DEMO

FRAMES = 30
MEASURED = 0.04  # fraction of the non-sky pixels a scan hits


def velo_to_cam() -> np.ndarray:
    """KITTI's axes (LiDAR x forward, y left, z up -> camera x right, y down, z forward), a small
    mounting rotation and a lever arm."""
    T = np.eye(4)
    axes = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    T[:3, :3] = quat_to_matrix(np.array([0.999, 0.01, -0.02, 0.015]) / np.linalg.norm([0.999, 0.01, -0.02, 0.015])) @ axes
    T[:3, 3] = [0.27, -0.08, -0.06]
    return T


def synthetic_scan(truth: np.ndarray, K: np.ndarray, T: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray]:
    """(points [N, 3] in the sensor frame, pixel mask of the returns that must win): returns at the
    centres of a random sparse set of surface pixels, plus a farther return behind half of them
    (hidden: the z-buffer keeps the nearer), returns behind the camera and beside the image."""
    h, w = truth.shape
    rows, cols = np.nonzero(truth > 0)
    pick = rng.choice(len(rows), int(MEASURED * len(rows)), replace=False)
    rows, cols = rows[pick], cols[pick]
    z = truth[rows, cols].astype(np.float64)
    rays = np.stack([cols + 0.5, rows + 0.5, np.ones(len(rows))], 1) @ np.linalg.inv(K).T
    near = rays * z[:, None]
    far = rays[::2] * (1.5 * z[::2])[:, None]
    behind = near[:50] * np.array([1.0, 1.0, -1.0])
    beside = rays[:50] * 20.0 + np.array([3.0 * w / K[0, 0] * 20.0, 0.0, 0.0])
    cam = np.concatenate([far, near, behind, beside])  # the hidden returns come first
    mask = np.zeros((h, w), bool)
    mask[rows, cols] = True
    sensor = conventions.invert_rigid(T)
    return cam @ sensor[:3, :3].T + sensor[:3, 3], mask


@pytest.fixture(scope="module")
def demo_scans(tmp_path_factory):
    """A copy of the demo manifest (its depth still the dense Cycles maps), scans in three formats
    named 0..29 (10 sorts after 9), the calibration file and each frame's truth and mask."""
    root = tmp_path_factory.mktemp("lidar")
    pkg = root / "pkg"
    pkg.mkdir()
    shutil.copy(DEMO / "manifest.json", pkg / "manifest.json")
    m = load_manifest(DEMO)
    cam = m.cameras[0]
    T = velo_to_cam()
    rng = np.random.default_rng(0)
    scans = root / "scans"
    scans.mkdir()
    truths, masks = [], []
    for i in range(FRAMES):
        truth = read_image(m.resolve(cam.frames[i].depth))[..., 0]
        pts, mask = synthetic_scan(truth, cam.frames[i].K, T, rng)
        if i < 10:  # KITTI velodyne: float32 x, y, z, reflectance
            np.column_stack([pts, rng.uniform(0, 1, len(pts))]).astype("<f4").tofile(scans / f"{i}.bin")
        elif i < 20:
            np.savez(scans / f"{i}.npz", points=pts.astype(np.float32))
        else:
            write_points(scans / f"{i}.ply", pts, np.zeros_like(pts))
        truths.append(truth)
        masks.append(mask)
    calib = root / "calib.txt"
    calib.write_text(" ".join(f"{v:.17g}" for v in T[:3].ravel()) + "\n")
    return pkg, scans, calib, truths, masks


def test_imported_depth_is_the_truth_at_the_scanned_pixels_and_unmeasured_elsewhere(demo_scans, capsys):
    pkg, scans, calib, truths, masks = demo_scans
    before = (pkg / "manifest.json").read_text()
    assert main(["import", "lidar", str(pkg), str(scans), "--sensor-to-camera", str(calib), "--quiet"]) == 2
    assert "already has depth maps" in capsys.readouterr().err
    assert (pkg / "manifest.json").read_text() == before and not (pkg / "lidar_depth").exists()

    assert main(["import", "lidar", str(pkg), str(scans), "--sensor-to-camera", str(calib), "--force",
                 "--quiet"]) == 0
    m = load_manifest(pkg)
    cam = m.cameras[0]
    assert cam.depth_zero == "unmeasured"
    assert json.loads((pkg / "manifest.json").read_text())["cameras"][0]["depth_zero"] == "unmeasured"
    for i in range(FRAMES):
        stored = read_image(m.resolve(cam.frames[i].depth))[..., 0]
        truth, mask = truths[i], masks[i]
        np.testing.assert_allclose(stored[mask], truth[mask], rtol=1e-5)  # the nearer return won
        assert np.all(stored[~mask] == 0)
        decoded = read_depth(m, cam, i)
        assert np.isnan(decoded[~mask]).all() and not np.isinf(decoded).any()  # gaps are not sky
    assert 0.01 < np.mean([mk.mean() for mk in masks]) < 0.05


def test_kitti_calibration_composes_the_rectification_and_plain_numbers_are_as_written(tmp_path):
    """Camera 0 of an object-layout file is the rectified Velodyne transform (the layouts and the
    other cameras: test_kitti_mono.py); 16 numbers are a 4x4 into the package camera."""
    T = velo_to_cam()
    rect = quat_to_matrix(np.array([1.0, 0.004, -0.003, 0.002]) / np.linalg.norm([1.0, 0.004, -0.003, 0.002]))
    f = tmp_path / "calib.txt"
    f.write_text("P2: " + " ".join(["1"] * 12) + "\n"
                 + "R0_rect: " + " ".join(f"{v:.17g}" for v in rect.ravel()) + "\n"
                 + "Tr_velo_to_cam: " + " ".join(f"{v:.17g}" for v in T[:3].ravel()) + "\n")
    R4 = np.eye(4)
    R4[:3, :3] = rect
    got, how = read_sensor_to_camera(f)
    np.testing.assert_allclose(got, R4 @ T, atol=1e-12)
    assert "camera 0 (--kitti-camera N for another)" in how
    f.write_text(" ".join(f"{v:.17g}" for v in T.ravel()))
    got, how = read_sensor_to_camera(f, kitti_camera=2)
    np.testing.assert_allclose(got, T, atol=1e-12)
    assert how.startswith("16 numbers")


def test_z_buffer_keeps_the_nearest_return_and_drops_what_is_too_near():
    K = conventions.intrinsics(10.0, 10.0, 4.0, 3.0)
    pts = np.array([[0.0, 0.0, 5.0], [0.0, 0.0, 3.0], [0.0, 0.0, 4.0],  # one pixel, three returns
                    [0.05, 0.0, 0.2],  # nearer than min_depth_m
                    [-0.5, -0.4, 1.0]])  # u = 4 - 5 = -1: left of the image
    d = sparse_depth(pts, np.eye(4), K, 8, 6, min_depth_m=0.5)
    assert d[3, 4] == 3.0 and np.count_nonzero(d) == 1


def test_a_transposed_npz_scan_is_refused_saying_so(tmp_path):
    np.savez(tmp_path / "a.npz", points=np.zeros((3, 300), np.float32))
    with pytest.raises(InputError, match=r"a.npz: points: expected numbers \[N, 3 to 16\].*\[3, 300\].*transpose"):
        read_scan(tmp_path / "a.npz")
    np.savez(tmp_path / "b.npz", points=np.ones((300, 5), np.float32))  # x, y, z and two more: fine
    assert read_scan(tmp_path / "b.npz").shape == (300, 3)


def test_scans_drop_non_finite_points(tmp_path):
    pts = np.array([[1.0, 2.0, 3.0, 0.5], [np.nan, 0.0, 0.0, 0.1], [4.0, np.inf, 6.0, 0.2]], "<f4")
    pts.tofile(tmp_path / "a.bin")
    np.testing.assert_array_equal(read_scan(tmp_path / "a.bin"), [[1.0, 2.0, 3.0]])


@pytest.mark.parametrize("break_it, field", [
    (lambda scans, calib: (scans / "17.npz").unlink(), "SCANS_DIR"),
    (lambda scans, calib: (scans / "25.ply").write_bytes((scans / "25.ply").read_bytes()[:-7]), "element vertex"),
    (lambda scans, calib: (scans / "3.bin").write_bytes(b"\0" * 20), "points"),
    (lambda scans, calib: (scans / "3.bin").write_bytes(b""), "points"),
    (lambda scans, calib: np.savez(scans / "12.npz", xyz=np.zeros((4, 3))), "points"),
    (lambda scans, calib: calib.write_text(" ".join(["2"] * 12)), "transform"),
    (lambda scans, calib: calib.write_text("Tr_velo_to_cam: 1 0 0\n"), "Tr_velo_to_cam"),
])
def test_bad_input_names_the_file_and_field_and_writes_nothing(demo_scans, tmp_path, capsys, break_it, field):
    pkg, scans, calib, _, _ = demo_scans
    work = tmp_path / "w"
    shutil.copytree(scans, work / "scans")
    shutil.copy(calib, work / "calib.txt")
    (work / "pkg").mkdir()
    shutil.copy(DEMO / "manifest.json", work / "pkg" / "manifest.json")
    break_it(work / "scans", work / "calib.txt")
    before = (work / "pkg" / "manifest.json").read_text()
    assert main(["import", "lidar", str(work / "pkg"), str(work / "scans"), "--sensor-to-camera",
                 str(work / "calib.txt"), "--force", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f": {field}: " in err[0]
    assert (work / "pkg" / "manifest.json").read_text() == before
    assert sorted(p.name for p in (work / "pkg").iterdir()) == ["manifest.json"]


def _fresh_package(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    shutil.copy(DEMO / "manifest.json", pkg / "manifest.json")
    return pkg


@pytest.mark.parametrize("extra, field", [(["--camera", "rear"], "--camera"), (["--min-depth", "-1"], "--min-depth")])
def test_bad_options_are_refused(demo_scans, tmp_path, capsys, extra, field):
    _, scans, calib, _, _ = demo_scans
    pkg = _fresh_package(tmp_path)
    try:  # found by argparse (exits) or after parsing (returns)
        code = main(["import", "lidar", str(pkg), str(scans), "--sensor-to-camera", str(calib), "--force",
                     "--quiet", *extra])
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    assert f"{field}: " in capsys.readouterr().err
    assert sorted(p.name for p in pkg.iterdir()) == ["manifest.json"]


def test_a_package_leading_the_depth_folder_elsewhere_is_refused(demo_scans, tmp_path, capsys):
    _, scans, calib, _, _ = demo_scans
    pkg = _fresh_package(tmp_path)
    outside = tmp_path / "outside"
    outside.mkdir()
    (pkg / "lidar_depth").symlink_to(outside)
    args = ["import", "lidar", str(pkg), str(scans), "--sensor-to-camera", str(calib), "--force", "--quiet"]
    assert main(args) == 2
    assert "leads outside the package" in capsys.readouterr().err and not any(outside.iterdir())
    (pkg / "lidar_depth").unlink()
    (pkg / "lidar_depth").write_text("not a folder")
    assert main(args) == 2
    assert "lidar_depth: is a file" in capsys.readouterr().err
