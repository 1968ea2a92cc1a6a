"""KITTI raw drives in (``symdrive import kitti-raw``): a drive written in KITTI's raw layout from
known IMU poses (as OXTS latitude, longitude, altitude and angles through the devkit's formulas
inverted), a known rig calibration, LiDAR returns at known world points and a tracklet of a known
moving box comes back within float64 round-off; pykitti reads the same files to the same poses
and calibration; bad input exits 2 naming the file and the field and writes nothing."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.conventions import invert_rigid
from symdrive_core.importers.kitti_raw import KittiRawConfig, read_kitti_raw
from symdrive_core.importers.oxts import EARTH_RADIUS_M, euler_rotation
from symdrive_core.io.images import read_image, write_image
from symdrive_core.io.points import read_points
from symdrive_core.rotations import rotation_vector_matrix
from symdrive_core.scene import load_manifest

from . import drives
from .drives import moved, numbers, rigid

DATE, DRIVE = "2011_09_26", "0005"
N_FRAMES, WIDTH, HEIGHT = 8, 64, 32
FX, CX, CY = 30.0, 31.5, 15.5  # KITTI's pixel centres at integers
K = np.array([[FX, 0.0, CX], [0.0, FX, CY], [0.0, 0.0, 1.0]])
FIRST_NS = 964389445  # the first frame's time past the second, in nanoseconds
LAT0, LON0, ALT0 = 49.011, 8.4229, 112.9
GROUND_Z = -0.93  # the road below the IMU in the source frame (East-North-Up, origin the first fix)
OFFSETS = {0: 0.0, 1: -0.54, 2: 0.06, 3: -0.47}  # P_rect_0i = K [I | (t, 0, 0)]
CAR_WLH = (1.8, 4.2, 1.5)
TOL_M = 1e-7  # round-off of Mercator coordinates near 5.4e6 m (measured: 4e-9 m)


def rot(rx, ry, rz):
    return euler_rotation(rx, ry, rz)


# The rig: IMU -> Velodyne, Velodyne -> unrectified camera 0, the rectifying rotation.
IMU_TO_VELO = rigid(rot(0.002, -0.011, 0.005), [-0.8087, 0.3196, -0.7997])
VELO_TO_CAM = rigid(np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]) @ rot(0.004, -0.007, 0.013),
                    [-0.0041, -0.0763, -0.2718])
R_RECT = rot(0.006, -0.003, 0.0021)


def camera_from_velo(i: int) -> np.ndarray:
    return rigid(np.eye(3), [OFFSETS[i], 0.0, 0.0]) @ rigid(R_RECT, np.zeros(3)) @ VELO_TO_CAM


def world_from_imu(k: int) -> np.ndarray:
    """The known trajectory: a gentle left bend on a level road, with some roll and pitch."""
    return rigid(rot(0.004 * k, 0.01 * (-1) ** k, 0.05 * k), [1.5 * k, 0.1 * k * k, 0.0])


def world_from_camera(i: int, k: int) -> np.ndarray:
    return world_from_imu(k) @ invert_rigid(camera_from_velo(i) @ IMU_TO_VELO)


def world_from_velo(k: int) -> np.ndarray:
    return world_from_imu(k) @ invert_rigid(IMU_TO_VELO)


def car_box(k: int) -> np.ndarray:
    """The tracked car's box (3DRealCar axes, origin at its centre) in the source frame."""
    return rigid(rot(0.0, 0.0, 0.1 + 0.02 * k), [9.0 + 1.2 * k, 3.0, GROUND_Z + CAR_WLH[2] / 2])


def world_points() -> np.ndarray:
    """The road ahead and beside the path, and a wall that hides part of it."""
    return drives.road_and_wall(GROUND_Z)


# ---------------------------------------------------------------- writing a drive


def mercator(lat, lon, alt, scale):
    return np.array([scale * lon * np.pi * EARTH_RADIUS_M / 180.0,
                     scale * EARTH_RADIUS_M * np.log(np.tan((90.0 + lat) * np.pi / 360.0)), alt])


def oxts_line(k: int, fix=None, velocity=(0.1, 0.1, 0.1), rate=(0.1, 0.1, 0.1)) -> str:
    """The devkit's formulas inverted: the fix and angles that give ``world_from_imu(k)`` (or the
    pose ``fix``), with the record's velocity (vf, vl, vu) and angular rate (wf, wl, wu)."""
    pose = world_from_imu(k) if fix is None else fix
    scale = np.cos(LAT0 * np.pi / 180.0)
    t = mercator(LAT0, LON0, ALT0, scale) + pose[:3, 3]
    lon = t[0] * 180.0 / (scale * np.pi * EARTH_RADIUS_M)
    lat = np.arctan(np.exp(t[1] / (scale * EARTH_RADIUS_M))) * 360.0 / np.pi - 90.0
    R = pose[:3, :3]
    yaw, pitch, roll = np.arctan2(R[1, 0], R[0, 0]), -np.arcsin(R[2, 0]), np.arctan2(R[2, 1], R[2, 2])
    rest = [0.1, 0.1, *velocity] + [0.1] * 9 + [*rate] + [0.5, 0.05] + [4, 11, 5, 5, 5]
    return " ".join(repr(float(v)) for v in [lat, lon, t[2], roll, pitch, yaw]) + " " + " ".join(map(str, rest))


def write_calibration(date_dir) -> None:
    (date_dir / "calib_cam_to_cam.txt").write_text(
        drives.cam_to_cam(K, WIDTH, HEIGHT, {i: (tx, R_RECT) for i, tx in OFFSETS.items()}))
    for name, T in (("calib_velo_to_cam.txt", VELO_TO_CAM), ("calib_imu_to_velo.txt", IMU_TO_VELO)):
        extra = "delta_f: 0 0\ndelta_c: 0 0\n" if name == "calib_velo_to_cam.txt" else ""
        (date_dir / name).write_text(f"calib_time: 15-Mar-2012 11:37:16\nR: {numbers(T[:3, :3])}\n"
                                     f"T: {numbers(T[:3, 3])}\n{extra}")


def tracklet_pose(k: int) -> str:
    """The car's box at frame k as the tracklet writes it: bottom centre and ZYX angles, Velodyne frame."""
    M = invert_rigid(world_from_velo(k)) @ car_box(k)
    R = M[:3, :3]
    bottom = M[:3, 3] - R @ [0.0, 0.0, CAR_WLH[2] / 2]
    angles = np.arctan2(R[2, 1], R[2, 2]), -np.arcsin(R[2, 0]), np.arctan2(R[1, 0], R[0, 0])
    fields = dict(zip(("tx", "ty", "tz", "rx", "ry", "rz"), (*bottom, *angles)))
    flags = "<state>1</state><occlusion>0</occlusion><occlusion_kf>0</occlusion_kf><truncation>0</truncation>"
    return ('<item class_id="3" tracking_level="0" version="2">' + "".join(f"<{k}>{v!r}</{k}>" for k, v in
            ((key, float(value)) for key, value in fields.items())) + flags + "</item>")


def tracklet(kind: str, wlh, first: int, poses: list[str]) -> str:
    w, l, h = wlh
    return (f'<item class_id="1" tracking_level="0" version="1"><objectType>{kind}</objectType><h>{h}</h><w>{w}</w>'
            f"<l>{l}</l><first_frame>{first}</first_frame><poses class_id=\"2\" tracking_level=\"0\" version=\"0\">"
            f"<count>{len(poses)}</count><item_version>2</item_version>{''.join(poses)}</poses>"
            "<finished>1</finished></item>")


def write_tracklets(path, items: list[str]) -> None:
    path.write_text('<?xml version="1.0" encoding="UTF-8" standalone="yes" ?>\n<!DOCTYPE boost_serialization>\n'
                    '<boost_serialization signature="serialization::archive" version="9">\n'
                    f'<tracklets class_id="0" tracking_level="0" version="0"><count>{len(items)}</count>'
                    f"<item_version>1</item_version>{''.join(items)}</tracklets></boost_serialization>\n")


def write_drive(root):
    """``root/DATE/DATE_drive_NNNN_sync`` as KITTI ships it; returns the drive folder."""
    date_dir = root / DATE
    drive = date_dir / f"{DATE}_drive_{DRIVE}_sync"
    rng = np.random.default_rng(3)
    for sub in ("image_02/data", "image_03/data", "oxts/data", "velodyne_points/data"):
        (drive / sub).mkdir(parents=True)
    write_calibration(date_dir)
    pts = world_points()
    for k in range(N_FRAMES):
        name = f"{k:010d}"
        for i in (2, 3):
            write_image(drive / f"image_{i:02d}" / "data" / f"{name}.png",
                        rng.integers(0, 256, (HEIGHT, WIDTH, 3)).astype(np.float32) / 255.0)
        (drive / "oxts" / "data" / f"{name}.txt").write_text(oxts_line(k) + "\n")
        drives.write_velodyne(drive / "velodyne_points" / "data" / f"{name}.bin", pts, world_from_velo(k))
    for sub in ("image_02", "image_03", "oxts", "velodyne_points"):
        (drive / sub / "timestamps.txt").write_text(drives.timestamps("2011-09-26 13:02", 25, FIRST_NS, N_FRAMES))
    write_tracklets(drive / "tracklet_labels.xml",
                    [tracklet("Car", CAR_WLH, 1, [tracklet_pose(k) for k in range(1, N_FRAMES)]),
                     tracklet("Pedestrian", (0.6, 0.8, 1.7), 0, [tracklet_pose(0)])])
    return drive


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    return write_drive(tmp_path_factory.mktemp("kitti_raw"))


@pytest.fixture(scope="module")
def package(drive, tmp_path_factory):
    return drives.imported(["import", "kitti-raw", str(drive)], tmp_path_factory)


# ---------------------------------------------------------------- round trip


def test_poses_come_back_in_the_source_frame(package):
    assert [c.name for c in package.cameras] == ["image_02", "image_03"]
    drives.assert_cameras(package, lambda camera, k: world_from_camera(int(camera[-2:]), k),
                          lambda camera: K + [[0, 0, 0.5], [0, 0, 0.5], [0, 0, 0]], TOL_M)
    assert package.source["frame_names"] == [f"{k:010d}" for k in range(N_FRAMES)]
    expected = [(FIRST_NS + drives.STEP_NS * k) / 1e9 - FIRST_NS / 1e9 for k in range(N_FRAMES)]
    assert np.allclose([f.timestamp for f in package.frames], expected, rtol=0, atol=1e-9)


def test_the_ground_is_the_lidar_road_and_the_world_metric(package):
    """The LiDAR's road becomes z = 0 of a metric world (the rig's roll and pitch move the cameras,
    whose constant height the fit also weighs, by 1 cm)."""
    drives.assert_metric_ground(package, world_points()[:-drives.WALL_POINTS], 0.02)


def test_every_camera_gets_the_scans_as_sparse_depth(drive, package):
    def want(camera: str, k: int) -> np.ndarray:
        scan = np.fromfile(drive / "velodyne_points" / "data" / f"{k:010d}.bin", "<f4").reshape(-1, 4)[:, :3]
        return drives.expected_depth(moved(camera_from_velo(int(camera[-2:])), scan.astype(np.float64)), K,
                                     WIDTH, HEIGHT)

    assert [c.name for c in package.cameras] == ["image_02", "image_03"]
    drives.assert_sparse_depth(package, want, rtol=1e-7)


def test_the_lidar_points_are_the_first_cameras_returns_coloured_there(drive):
    d = read_kitti_raw(drive, replace(KittiRawConfig(), lidar_points=10**6))  # every return kept
    world = world_points()
    col, row, seen = drives.landing(moved(invert_rigid(world_from_camera(2, 0)), world), K, WIDTH, HEIGHT)
    n = int(seen.sum())
    assert n > 200
    # the first scan's returns come first, in the scan's order; the scan holds float32 coordinates
    assert np.abs(d.source.points[:n] - world[seen]).max() < 1e-5
    image = read_image(drive / "image_02" / "data" / "0000000000.png", channels=3)
    assert np.array_equal(d.source.colors[:n], image[row[seen].astype(int), col[seen].astype(int)])
    assert len(read_kitti_raw(drive).source.points) <= KittiRawConfig().lidar_points
    assert np.array_equal(d.source.point_frames[:n], np.zeros(n)) and d.source.point_frames[n] == 1


def test_held_out_frames_returns_never_reach_the_start_points(drive, tmp_path, capsys):
    """Imported with every 4th frame held out (frames 2 and 6), the start points are the training
    frames' returns, with the colours the training frames' images gave them."""
    every = read_kitti_raw(drive).source
    train = np.isin(every.point_frames, [0, 1, 3, 4, 5, 7])
    assert 0 < train.sum() < len(train)
    out = tmp_path / "pkg"
    assert main(["import", "kitti-raw", str(drive), "--out", str(out), "--heldout-every", "4", "--quiet"]) == 0
    assert f"left out {(~train).sum()} LiDAR returns of held-out frames" in capsys.readouterr().out
    m = load_manifest(out)
    assert m.ground_truth["heldout_frames"] == [2, 6]
    _, colors = read_points(m.resolve(m.background_points))
    np.testing.assert_allclose(colors, every.colors[train], atol=1 / 255)  # the file holds 8-bit colours


def test_the_tracklet_comes_back_as_an_existing_actor(package, capsys):
    (car,) = package.actors
    assert car.id == "tracklet_0" and car.kind == "existing" and car.splats is None
    assert np.allclose(car.wlh, CAR_WLH, rtol=0, atol=1e-12)
    drives.assert_actor_poses(package, car, lambda k: None if k == 0 else car_box(k), TOL_M)


LAGS_S = [0.0016, 0.0082, 0.0049, 0.0014, 0.0079, 0.0044, 0.0111, 0.0077]  # fix to image, drive 0009's
VELOCITY, RATE = (10.6, 0.03, -0.02), (0.002, -0.004, 0.024)  # m/s and rad/s along and about the IMU's axes


def lagging_drive(drive, root):
    """(``drive`` copied with each OXTS fix ``LAGS_S`` before its frame's images, taken while the
    IMU moved at ``VELOCITY`` and turned at ``RATE``: where the known pose was that long before;
    the first fix, the source frame's origin)."""
    import shutil

    out = root / DATE / drive.name
    shutil.copytree(drive.parent, root / DATE)
    stamps, fixes = [], []
    for k, lag in enumerate(LAGS_S):
        image_time = world_from_imu(k)
        R = image_time[:3, :3] @ rotation_vector_matrix(-np.asarray(RATE) * lag)
        fixes.append(rigid(R, image_time[:3, 3] - R @ np.asarray(VELOCITY) * lag))
        (out / "oxts" / "data" / f"{k:010d}.txt").write_text(oxts_line(k, fixes[-1], VELOCITY, RATE) + "\n")
        ns = FIRST_NS + drives.STEP_NS * k - round(lag * 1e9)
        stamps.append(f"2011-09-26 13:02:{25 + ns // 10**9:02d}.{ns % 10**9:09d}\n")
    (out / "oxts" / "timestamps.txt").write_text("".join(stamps))
    return out, fixes[0][:3, 3]


def test_each_pose_is_carried_from_its_fix_to_its_image_time(drive, tmp_path):
    """A fix a few milliseconds before its images is carried to the images' time by the record's
    velocity and angular rate; without the OXTS times the fix is taken as it is (the devkit's)."""
    lagging, origin = lagging_drive(drive, tmp_path)
    shift = rigid(np.eye(3), -origin)
    d = read_kitti_raw(lagging)
    for k, (cam2, cam3) in enumerate(zip(*d.source.grouped.table)):
        assert np.abs(cam2.c2w - shift @ world_from_camera(2, k)).max() < TOL_M
        assert np.abs(cam3.c2w - shift @ world_from_camera(3, k)).max() < TOL_M
    assert d.source.notes["oxts_to_image_s"] == pytest.approx({"min": min(LAGS_S), "max": max(LAGS_S)}, abs=1e-9)
    (lagging / "oxts" / "timestamps.txt").unlink()
    d = read_kitti_raw(lagging)
    moved_by = [np.linalg.norm(cam2.c2w[:3, 3] - (shift @ world_from_camera(2, k))[:3, 3]) for k, cam2 in
                enumerate(d.source.grouped.table[0])]
    assert np.allclose(moved_by, np.linalg.norm(VELOCITY) * np.asarray(LAGS_S), rtol=0.02)
    assert d.source.notes["oxts_to_image_s"] is None


def test_pykitti_reads_the_same_poses_and_calibration(drive):
    pykitti = pytest.importorskip("pykitti")
    data = pykitti.raw(str(drive.parent.parent), DATE, DRIVE)
    d = read_kitti_raw(drive)
    cams = d.cameras
    assert np.allclose(cams["image_02"].K - [[0, 0, 0.5], [0, 0, 0.5], [0, 0, 0]], data.calib.K_cam2, rtol=0,
                       atol=1e-12)
    assert np.allclose(cams["image_02"].velo_to_camera, data.calib.T_cam2_velo, rtol=0, atol=1e-12)
    assert np.allclose(cams["image_03"].velo_to_camera, data.calib.T_cam3_velo, rtol=0, atol=1e-12)
    assert np.allclose(cams["image_02"].imu_to_camera, data.calib.T_cam2_imu, rtol=0, atol=1e-12)
    for k, (cam2, cam3) in enumerate(zip(*d.source.grouped.table)):
        assert np.allclose(cam2.c2w, data.oxts[k].T_w_imu @ invert_rigid(data.calib.T_cam2_imu), rtol=0, atol=1e-9)
        assert np.allclose(cam3.c2w, data.oxts[k].T_w_imu @ invert_rigid(data.calib.T_cam3_imu), rtol=0, atol=1e-9)


def test_the_right_camera_as_lateral_truth(drive, tmp_path, capsys):
    out = tmp_path / "pkg"
    assert main(["import", "kitti-raw", str(drive), "--out", str(out), "--lateral-truth", "image_03",
                 "--quiet"]) == 0
    m = load_manifest(out)
    assert [c.name for c in m.cameras] == ["image_02"]
    assert m.effects.lateral_offsets == [round(OFFSETS[2] - OFFSETS[3], 4)]
    assert len(m.actors) == 1 and m.cameras[0].frames[0].depth is not None
    assert "image_03" in capsys.readouterr().out


def test_one_camera(drive, tmp_path):
    out = tmp_path / "pkg"
    assert main(["import", "kitti-raw", str(drive), "--out", str(out), "--cameras", "3", "--quiet"]) == 0
    m = load_manifest(out)
    assert [c.name for c in m.cameras] == ["image_03"] and len(m.frames) == N_FRAMES
    T = np.asarray(m.source["transform"])
    assert np.abs(invert_rigid(T) @ m.cameras[0].frames[4].camera_to_world - world_from_camera(3, 4)).max() < TOL_M
    assert main(["validate", str(out), "--allow-external-assets"]) == 0


def test_the_first_camera_named_is_the_packages_first(drive, tmp_path):
    out = tmp_path / "pkg"
    assert main(["import", "kitti-raw", str(drive), "--out", str(out), "--cameras", "3,2", "--quiet"]) == 0
    m = load_manifest(out)
    assert [c.name for c in m.cameras] == ["image_03", "image_02"]
    assert m.ground_truth["camera"] == "image_03"
    T = np.asarray(m.source["transform"])
    for c, i in zip(m.cameras, (3, 2)):
        assert np.abs(invert_rigid(T) @ c.frames[4].camera_to_world - world_from_camera(i, 4)).max() < TOL_M


# ---------------------------------------------------------------- bad input


def refused(drive, tmp_path, capsys, *needles):
    drives.refused(["import", "kitti-raw", str(drive)], tmp_path, capsys, *needles)


@pytest.fixture
def bad(tmp_path):
    return write_drive(tmp_path / "drive")


def test_missing_oxts_file(bad, tmp_path, capsys):
    (bad / "oxts" / "data" / "0000000003.txt").unlink()
    refused(bad, tmp_path, capsys, "0000000003.txt", "oxts", "not found")


def test_oxts_times_short_of_the_frames(bad, tmp_path, capsys):
    """The fixes' times carry each pose to its image's: a file that stops early is refused by name."""
    stamps = bad / "oxts" / "timestamps.txt"
    stamps.write_text("".join(stamps.read_text().splitlines(keepends=True)[:5]))
    refused(bad, tmp_path, capsys, "oxts/timestamps.txt", "no time for frame 0000000005", "line 6")


def test_camera_times_that_do_not_increase_are_refused_naming_the_line(bad, tmp_path, capsys):
    stamps = bad / "image_02" / "timestamps.txt"
    lines = stamps.read_text().splitlines(keepends=True)
    lines[4] = lines[3]  # frame 4 at frame 3's instant
    stamps.write_text("".join(lines))
    refused(bad, tmp_path, capsys, "image_02/timestamps.txt", "line 5", "frame 4's time", "is not after frame 3's")


def test_missing_oxts_line(bad, tmp_path, capsys):
    (bad / "oxts" / "data" / "0000000003.txt").write_text("\n")
    refused(bad, tmp_path, capsys, "0000000003.txt", "line 1", "expected one line")


def test_oxts_line_with_the_wrong_field_count(bad, tmp_path, capsys):
    path = bad / "oxts" / "data" / "0000000005.txt"
    path.write_text(" ".join(path.read_text().split()[:29]) + "\n")
    refused(bad, tmp_path, capsys, "0000000005.txt", "line 1", "expected 30", "got 29")


@pytest.mark.parametrize("file,key", [("calib_cam_to_cam.txt", "P_rect_02"), ("calib_cam_to_cam.txt", "R_rect_00"),
                                      ("calib_imu_to_velo.txt", "R"), ("calib_velo_to_cam.txt", "T")])
def test_calibration_with_the_wrong_field_count(bad, tmp_path, capsys, file, key):
    path = bad.parent / file
    lines = [f"{line} 1.0" if line.startswith(f"{key}:") else line for line in path.read_text().splitlines()]
    path.write_text("\n".join(lines) + "\n")
    refused(bad, tmp_path, capsys, file, f": {key}: ", "numbers, got")


def test_scan_count_not_the_image_count(bad, tmp_path, capsys):
    (bad / "velodyne_points" / "data" / "0000000006.bin").unlink()
    refused(bad, tmp_path, capsys, "velodyne_points", "7 scans for 8 frames", "0000000006")


def test_tracklet_with_no_poses(bad, tmp_path, capsys):
    write_tracklets(bad / "tracklet_labels.xml", [tracklet("Car", CAR_WLH, 1, [tracklet_pose(1)]),
                                                  tracklet("Van", CAR_WLH, 0, [])])
    refused(bad, tmp_path, capsys, "tracklet_labels.xml", "tracklets.item[1].poses", "no poses")


def test_camera_without_images(bad, tmp_path, capsys):
    rc = main(["import", "kitti-raw", str(bad), "--out", str(tmp_path / "pkg"), "--cameras", "2,1", "--quiet"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "image_01" in err and "--cameras" in err, err
    assert not (tmp_path / "pkg").exists()


def test_an_image_of_another_size_than_its_camera_is_refused_naming_it(bad, tmp_path, capsys):
    """The first camera's images are read for the LiDAR's colours before the package checks them."""
    write_image(bad / "image_02" / "data" / "0000000001.png", np.zeros((HEIGHT, WIDTH - 1, 3), np.float32))
    refused(bad, tmp_path, capsys, "image_02/data/0000000001.png", f"image is {WIDTH - 1}x{HEIGHT}",
            f"is {WIDTH}x{HEIGHT}")


@pytest.mark.parametrize("index, value", [(0, "90"), (0, "-91"), (1, "181"), (2, "1e308")])
def test_an_oxts_fix_that_is_no_place_on_earth_is_refused_naming_the_file(bad, tmp_path, capsys, index, value):
    path = bad / "oxts" / "data" / "0000000003.txt"
    fields = path.read_text().split()
    fields[index] = value
    path.write_text(" ".join(fields) + "\n")
    refused(bad, tmp_path, capsys, "0000000003.txt", ": line 1: ", "no fix on Earth")


def test_an_empty_scan_is_refused_naming_it(bad, tmp_path, capsys):
    (bad / "velodyne_points" / "data" / "0000000002.bin").write_bytes(b"")
    refused(bad, tmp_path, capsys, "0000000002.bin", ": points: ", "0 bytes")


def test_a_frame_one_camera_lacks_is_named_at_that_camera(bad, tmp_path, capsys):
    (bad / "image_03" / "data" / "0000000004.png").unlink()
    refused(bad, tmp_path, capsys, "image_03/data: --cameras: no 0000000004.png, which image_02 records")
