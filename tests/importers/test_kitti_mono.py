"""A KITTI sequence with one camera (``image_2`` alone, as most published excerpts hold) imports as
a one-camera package that notes which KITTI camera it holds, and its Velodyne scans, read with
any of KITTI's calibration layouts, land on that camera's pixels: points placed at known pixels
of camera 2 through KITTI's own chain (``P2 R_rect Tr_velo_cam``) come back at those pixels with
their depth, where the uncomposed transform (camera 0's) puts them beside them."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.io.images import read_image
from symdrive_core.io.ply import write_splats
from symdrive_core.rotations import quat_to_matrix
from symdrive_core.scene import load_manifest

from .demo_formats import CAMERA_HEIGHT, DEMO, demo_splats
from .test_bad_input import assert_refused
from .test_lidar import velo_to_cam

FRAMES = 6
POINTS = 300  # returns per scan
# Each camera's t in P_i = K [I | t] (metres): camera i sits at -t in rectified camera 0's frame;
# KITTI's colour camera 2 sits 6 cm to the left of camera 0, camera 3 0.47 m to its right.
T_CAM = {0: [0.0, 0.0, 0.0], 1: [-0.537, 0.0, 0.0], 2: [0.0622, -0.0003, 0.0027], 3: [-0.4706, 0.003, 0.0027]}
KITTI_CAMERA = {"image_0": 0, "image_1": 1, "image_2": 2, "image_3": 3, "image_l": 0, "image_r": 1}


def kitti_K() -> np.ndarray:
    """The demo camera's K with KITTI's pixel centres (at integers)."""
    K = load_manifest(DEMO).cameras[0].frames[0].K.copy()
    K[:2, 2] -= 0.5
    return K


def projection(i: int) -> np.ndarray:
    K = kitti_K()
    return K @ np.hstack([np.eye(3), np.array(T_CAM[i])[:, None]])


def rect() -> np.ndarray:
    """A rectifying rotation as KITTI's (a few tenths of a degree)."""
    R = np.eye(4)
    R[:3, :3] = quat_to_matrix(np.array([1.0, 0.004, -0.003, 0.002]) / np.linalg.norm([1.0, 0.004, -0.003, 0.002]))
    return R


def numbers(M) -> str:
    return " ".join(f"{v:.12e}" for v in np.ravel(M))


def p_lines(prefix: str = "P", sep: str = ": ") -> str:
    return "".join(f"{prefix}{i}{sep}{numbers(projection(i))}\n" for i in T_CAM)


def write_calibration(folder, layout: str):
    """The rig (``velo_to_cam`` before rectification, ``rect``, ``T_CAM``) in one KITTI layout;
    returns the file to pass as --sensor-to-camera."""
    folder.mkdir(parents=True, exist_ok=True)
    Tr, R = velo_to_cam(), rect()
    other = numbers(np.hstack([np.eye(3), [[0.8], [-0.3], [0.8]]]))  # Tr_imu_velo: not read
    if layout == "odometry":
        text = p_lines() + f"Tr: {numbers((R @ Tr)[:3])}\n"
    elif layout == "tracking":
        text = p_lines() + f"R_rect {numbers(R[:3, :3])}\nTr_velo_cam {numbers(Tr[:3])}\nTr_imu_velo {other}\n"
    elif layout == "tracking_3x4":
        text = p_lines() + f"R_rect {numbers(R[:3])}\nTr_velo_cam {numbers(Tr[:3])}\n"
    elif layout == "object":
        text = p_lines() + f"R0_rect: {numbers(R[:3, :3])}\nTr_velo_to_cam: {numbers(Tr[:3])}\nTr_imu_to_velo: {other}\n"
    else:  # raw: the date folder's two files
        (folder / "calib_cam_to_cam.txt").write_text(
            "calib_time: 09-Jan-2012 13:57:47\ncorner_dist: 9.950000e-02\n"
            + "".join(f"S_0{i}: 1.392000e+03 5.120000e+02\nR_0{i}: {numbers(np.eye(3))}\nT_0{i}: {numbers(T_CAM[i])}\n"
                      f"R_rect_0{i}: {numbers(R[:3, :3])}\nP_rect_0{i}: {numbers(projection(i))}\n" for i in T_CAM))
        (folder / "calib_velo_to_cam.txt").write_text(
            f"calib_time: 15-Mar-2012 11:37:16\nR: {numbers(Tr[:3, :3])}\nT: {numbers(Tr[:3, 3])}\n"
            "delta_f: 0.000000e+00 0.000000e+00\ndelta_c: 0.000000e+00 0.000000e+00\n")
        return folder / "calib_velo_to_cam.txt"
    (folder / "calib.txt").write_text(text)
    return folder / "calib.txt"


def write_sequence(root, folders=("image_2",)):
    """The demo's first frames as a KITTI odometry excerpt seen by ``folders`` (the demo camera is
    the first folder's KITTI camera), ``calib.txt`` of the odometry layout and camera 0's poses."""
    m = load_manifest(DEMO)
    cam = m.cameras[0]
    first = np.linalg.inv(cam.frames[0].camera_to_world)
    offset = np.eye(4)
    offset[:3, 3] = -np.array(T_CAM[KITTI_CAMERA[folders[0]]])  # where the camera sits in camera 0's frame
    poses = [first @ f.camera_to_world @ np.linalg.inv(offset) for f in cam.frames[:FRAMES]]
    for folder in folders:
        (root / folder).mkdir(parents=True)
        for i, f in enumerate(cam.frames[:FRAMES]):
            (root / folder / f"{i:06d}.png").hardlink_to(m.resolve(f.image))
    write_calibration(root, "odometry")
    (root / "poses.txt").write_text("".join(numbers(p[:3]) + "\n" for p in poses))
    write_splats(root / "splats.ply", demo_splats(500))  # so the import need not triangulate
    return root


def import_sequence(seq, out, capsys, *extra):
    rc = main(["import", "kitti", str(seq), "--splats", str(seq / "splats.ply"), "--out", str(out),
               "--camera-height", str(CAMERA_HEIGHT), "--copy-images", "--quiet", *extra])
    printed = capsys.readouterr()
    assert rc == 0, printed.err
    return load_manifest(out), printed.out


@pytest.mark.parametrize("folder", ["image_2", "image_0", "image_l", "image_3", "image_r"])
def test_one_camera_sequence_imports_as_one_camera_noting_its_kitti_camera(folder, tmp_path, capsys):
    seq = write_sequence(tmp_path / "seq", (folder,))
    m, printed = import_sequence(seq, tmp_path / "pkg", capsys)
    assert f"one camera: {folder} (KITTI camera {KITTI_CAMERA[folder]}), no lateral ground truth" in printed
    assert [c.name for c in m.cameras] == ["front"] and len(m.cameras[0].frames) == FRAMES
    assert not m.ground_truth.get("lateral") and not m.effects.lateral_offsets
    assert m.source["kitti_camera"] == KITTI_CAMERA[folder] and m.source["image_folder"] == folder
    assert "stereo_pair" not in m.source
    cam, demo = m.cameras[0], load_manifest(DEMO).cameras[0]
    np.testing.assert_allclose(cam.frames[0].K, demo.frames[0].K, atol=1e-9)
    for i in range(FRAMES):  # the camera is the demo camera: camera 0's poses moved by P_i's offset
        got = np.linalg.inv(cam.frames[0].camera_to_world) @ cam.frames[i].camera_to_world
        expected = np.linalg.inv(demo.frames[0].camera_to_world) @ demo.frames[i].camera_to_world
        np.testing.assert_allclose(got, expected, atol=1e-9)
    assert np.array_equal(read_image(m.resolve(cam.frames[3].image)), read_image(seq / folder / "000003.png"))


def test_a_stereo_pair_keeps_its_right_camera_as_lateral_truth_and_notes_the_left(tmp_path, capsys):
    seq = write_sequence(tmp_path / "seq", ("image_2", "image_3"))
    m, printed = import_sequence(seq, tmp_path / "pkg", capsys)
    assert "lateral ground truth: camera front_right" in printed and "one camera" not in printed
    assert [c.name for c in m.cameras] == ["front"]
    (entry,) = m.ground_truth["lateral"]
    assert abs(entry["offset_m"] - (T_CAM[2][0] - T_CAM[3][0])) < 1e-3  # 0.53 m between cameras 2 and 3
    assert m.source["kitti_camera"] == 2 and m.source["stereo_pair"] == ["image_2", "image_3"]


@pytest.fixture(scope="module")
def mono(tmp_path_factory):
    """A one-camera package of image_2 and scans of returns at known pixels of camera 2."""
    root = tmp_path_factory.mktemp("mono")
    seq = write_sequence(root / "seq")
    assert main(["import", "kitti", str(seq), "--splats", str(seq / "splats.ply"), "--out", str(root / "pkg"),
                 "--camera-height", str(CAMERA_HEIGHT), "--copy-images", "--quiet"]) == 0
    return root / "pkg", *write_scans(root / "velodyne", load_manifest(root / "pkg").cameras[0])


def write_scans(folder, cam):
    """Velodyne scans (.bin) of returns at random pixel centres of KITTI camera 2, placed through
    KITTI's chain: camera 2 -> rectified camera 0 (- t_2) -> camera 0 (R_rect^T) -> Velodyne.
    Returns (folder, per frame the pixels [N, 2] (row, col) and depths)."""
    rng = np.random.default_rng(4)
    folder.mkdir()
    K_inv = np.linalg.inv(kitti_K())
    to_velo = np.linalg.inv(rect() @ velo_to_cam())
    truth = []
    for i in range(FRAMES):
        flat = rng.choice(cam.width * cam.height, POINTS, replace=False)
        rows, cols = np.divmod(flat, cam.width)
        z = rng.uniform(2.0, 12.0, POINTS)
        cam2 = (np.stack([cols, rows, np.ones(POINTS)], 1) @ K_inv.T) * z[:, None]
        rect0 = cam2 - np.array(T_CAM[2])
        velo = rect0 @ to_velo[:3, :3].T + to_velo[:3, 3]
        np.column_stack([velo, rng.uniform(0, 1, POINTS)]).astype("<f4").tofile(folder / f"{i:06d}.bin")
        truth.append((rows, cols, z))
    return folder, truth


def import_lidar(pkg, scans, calib, tmp_path, capsys, *extra):
    work = tmp_path / "pkg"
    shutil.copytree(pkg, work)
    rc = main(["import", "lidar", str(work), str(scans), "--sensor-to-camera", str(calib), "--quiet", *extra])
    printed = capsys.readouterr()
    return rc, work, printed


def landed(work, truth) -> float:
    """The share of returns whose pixel holds their depth (within float32 round-off), after
    checking that no pixel holds depth that no return put there."""
    cam = load_manifest(work).cameras[0]
    hits = []
    for fi, (rows, cols, z) in enumerate(truth):
        depth = read_image(work / cam.frames[fi].depth)[..., 0]
        assert np.count_nonzero(depth) <= len(z)
        hits.append(np.isclose(depth[rows, cols], z, rtol=1e-5))
    return float(np.mean(hits))


@pytest.mark.parametrize("layout", ["odometry", "tracking", "tracking_3x4", "object", "raw"])
def test_every_kitti_layout_puts_the_returns_on_camera_2s_pixels(mono, layout, tmp_path, capsys):
    pkg, scans, truth = mono
    calib = write_calibration(tmp_path / "calib", layout)
    rc, work, printed = import_lidar(pkg, scans, calib, tmp_path, capsys)
    assert rc == 0, printed.err
    assert f"KITTI {layout.split('_')[0]} calibration" in printed.out and "rectified camera 2" in printed.out
    assert landed(work, truth) == 1.0


def test_the_sequences_own_calib_txt_is_read_and_camera_0_would_miss(mono, tmp_path, capsys):
    """The odometry ``Tr:`` line of the sequence's calib.txt; composed to camera 0 instead (as if
    the package held camera 0), the same returns land beside their pixels."""
    pkg, scans, truth = mono
    calib = pkg.parent / "seq" / "calib.txt"
    rc, work, printed = import_lidar(pkg, scans, calib, tmp_path / "a", capsys)
    assert rc == 0 and landed(work, truth) == 1.0
    rc, work, printed = import_lidar(pkg, scans, calib, tmp_path / "b", capsys, "--kitti-camera", "0")
    assert rc == 0 and "rectified camera 0" in printed.out
    print(f"composed to camera 0: {landed(work, truth):.1%} of the returns on their pixel")
    assert landed(work, truth) < 0.5


def test_a_package_that_does_not_say_its_kitti_camera_gets_camera_0_and_is_told(mono, tmp_path, capsys):
    pkg, scans, truth = mono
    bare = tmp_path / "bare"
    shutil.copytree(pkg, bare)
    text = (bare / "manifest.json").read_text().replace('"kitti_camera": 2', '"kitti_camera_was": 2')
    (bare / "manifest.json").write_text(text)
    calib = write_calibration(tmp_path / "calib", "tracking")
    rc, _, printed = import_lidar(bare, scans, calib, tmp_path / "a", capsys)
    assert rc == 0 and "does not say which KITTI camera it holds: camera 0 (--kitti-camera N" in printed.out
    rc, work, printed = import_lidar(bare, scans, calib, tmp_path / "b", capsys, "--kitti-camera", "2")
    assert rc == 0 and landed(work, truth) == 1.0


@pytest.mark.parametrize("layout, line, file, field", [
    ("odometry", ("Tr: ", "Tr: 1 0 0 0\nX: "), "calib.txt", "Tr"),
    ("odometry", ("P2: ", "P2: 7 0 "), "calib.txt", "P2"),
    ("tracking", ("R_rect ", "R_rect 1 0 0 0 1 "), "calib.txt", "R_rect"),
    ("tracking", ("Tr_velo_cam ", "Tr_velo_cam 1 2 3\nX "), "calib.txt", "Tr_velo_cam"),
    ("object", ("R0_rect: ", "R0_rect: 2 0 0 0 2 0 0 0 2\nX: "), "calib.txt", "R0_rect"),
    ("raw", ("T: ", "T: 0.1 0.2\nX: "), "calib_velo_to_cam.txt", "T"),
    ("raw", None, "calib_cam_to_cam.txt", "R_rect_00"),
])
def test_a_bad_calibration_names_the_file_and_field_and_writes_nothing(mono, layout, line, file, field, tmp_path,
                                                                       capsys):
    pkg, scans, _ = mono
    calib = write_calibration(tmp_path / "calib", layout)
    if line is None:
        (calib.parent / file).unlink()
    else:
        path = calib.parent / file
        path.write_text(path.read_text().replace(*line, 1))
    before = (pkg / "manifest.json").read_text()
    rc, work, printed = import_lidar(pkg, scans, calib, tmp_path, capsys)
    err = printed.err.strip()
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert f"{file}: {field}: " in err
    assert (work / "manifest.json").read_text() == before and not (work / "lidar_depth").exists()


def test_a_gap_in_the_frames_stays_a_gap_in_time(tmp_path, capsys):
    seq = write_sequence(tmp_path / "seq")
    (seq / "image_2" / "000002.png").unlink()
    m, _ = import_sequence(seq, tmp_path / "pkg", capsys)
    assert [f.timestamp for f in m.frames] == pytest.approx([0.0, 0.1, 0.3, 0.4, 0.5])


def test_text_files_saved_with_a_byte_order_mark_read_as_without(tmp_path, capsys):
    seq = write_sequence(tmp_path / "seq")
    for name in ("calib.txt", "poses.txt"):
        (seq / name).write_bytes(b"\xef\xbb\xbf" + (seq / name).read_bytes())
    m, _ = import_sequence(seq, tmp_path / "pkg", capsys)
    plain, _ = import_sequence(write_sequence(tmp_path / "plain"), tmp_path / "plain_pkg", capsys)
    np.testing.assert_array_equal(m.cameras[0].frames[4].camera_to_world, plain.cameras[0].frames[4].camera_to_world)


def test_times_that_do_not_increase_are_refused_naming_the_line(tmp_path, capsys):
    seq = write_sequence(tmp_path / "seq")
    (seq / "times.txt").write_text("0.0\n0.1\n0.2\n0.2\n0.4\n0.5\n")
    out = tmp_path / "pkg"
    rc = main(["import", "kitti", str(seq), "--splats", str(seq / "splats.ply"), "--out", str(out),
               "--camera-height", "1.6"])
    assert_refused(rc, capsys.readouterr().err.strip(), out, "times.txt: line 4: frame 3's time 0.2 s is not after")


def test_no_image_folder_is_refused_naming_the_sequence(tmp_path, capsys):
    seq = write_sequence(tmp_path / "seq")
    (seq / "image_2").rename(seq / "images")
    out = tmp_path / "pkg"
    rc = main(["import", "kitti", str(seq), "--out", str(out), "--camera-height", "1.6"])
    assert_refused(rc, capsys.readouterr().err.strip(), out, "SEQUENCE_DIR", "no image folder (image_2, image_0")


def test_an_image_named_by_a_digit_that_is_no_number_is_not_a_frame(tmp_path, capsys):
    """``².png`` is a digit to str.isdigit but no frame number: not read, as any other name."""
    seq = write_sequence(tmp_path / "seq")
    (seq / "image_2" / "\u00b2.png").write_bytes((seq / "image_2" / "000001.png").read_bytes())
    m, _ = import_sequence(seq, tmp_path / "pkg", capsys)
    assert len(m.frames) == FRAMES
