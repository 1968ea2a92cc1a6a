"""KITTI-360 sequences in (``symdrive import kitti-360``): a sequence written in KITTI-360's layout
from a known system-pose path, a known rig (rectifying rotations, cameras on the vehicle, the
Velodyne), LiDAR returns on a road and a wall, a moving car and a parked one as 3D boxes, and one
frame without a pose comes back within float64 round-off; kitti360scripts' own loaders read the
same files to the same poses, calibration and boxes; bad input exits 2 naming the file and the
field and writes nothing."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.conventions import invert_rigid
from symdrive_core.importers.kitti360 import read_kitti360
from symdrive_core.importers.oxts import euler_rotation as rot
from symdrive_core.io.images import write_image
from symdrive_core.scene import load_manifest

from . import drives
from .drives import moved, numbers, rigid

SEQ = "2013_05_28_drive_0000_sync"
N_FRAMES, UNPOSED = 8, 3  # images 0..7; frame 3 has no pose
POSED = [k for k in range(N_FRAMES) if k != UNPOSED]
WIDTH, HEIGHT = 64, 32
FX, CX, CY = 30.0, 31.5, 15.5  # KITTI-360's pixel centres at integers
K = np.array([[FX, 0.0, CX], [0.0, FX, CY], [0.0, 0.0, 1.0]])
BASELINE = 0.6  # rectified camera 1 this far along rectified camera 0's +x
ORIGIN = np.array([1023.4, 3871.2, 115.6])  # the path's start in the sequence's world (metres, z up)
GROUND_Z = ORIGIN[2] - 1.9
CAR_LWH = (4.3, 1.8, 1.5)
PARKED_LWH = (4.0, 1.7, 1.4)
TOL_M = 1e-9


# The rectified cameras' axes (x right, y down, z forward) in the system pose's (x forward, y left, z up).
Q = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]) @ rot(0.01, -0.02, 0.004)
R_RECT = {0: rot(0.004, -0.006, 0.002), 1: rot(-0.003, 0.005, -0.004)}
T0 = np.array([1.55, 0.25, -0.7])
# unrectified camera i -> the system pose: rectified camera i is (T_i R_rect_0i^-1), axes Q
CAM_TO_POSE = {0: rigid(Q @ R_RECT[0], T0), 1: rigid(Q @ R_RECT[1], T0 + Q @ [BASELINE, 0.0, 0.0])}
CAM0_TO_VELO = rigid(rot(0.01, 0.005, -0.012) @ np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]),
                     [0.8, -0.3, -0.75])


def world_from_pose(k: int) -> np.ndarray:
    """The known path: a gentle left bend on a level road, with some roll and pitch."""
    return rigid(rot(0.004 * k, 0.01 * (-1) ** k, 0.4 + 0.05 * k), ORIGIN + [1.5 * k, 0.1 * k * k, 0.0])


def world_from_camera(i: int, k: int) -> np.ndarray:
    """Rectified camera i at frame k."""
    return world_from_pose(k) @ CAM_TO_POSE[i] @ invert_rigid(rigid(R_RECT[i], np.zeros(3)))


def world_from_velo(k: int) -> np.ndarray:
    return world_from_pose(k) @ CAM_TO_POSE[0] @ invert_rigid(CAM0_TO_VELO)


def car_box(k: int) -> np.ndarray:
    """The moving car's box (3DRealCar axes, origin at its centre) in the world."""
    c, s = np.cos(0.4), np.sin(0.4)
    return rigid(rot(0.0, 0.0, 0.45 + 0.02 * k), ORIGIN + [9.0 * c - 3.0 * s + 1.2 * k, 9.0 * s + 3.0 * c,
                                                            GROUND_Z - ORIGIN[2] + CAR_LWH[2] / 2])


PARKED = rigid(rot(0.0, 0.0, 0.4 + np.pi), ORIGIN + [14.0, 1.0, GROUND_Z - ORIGIN[2] + PARKED_LWH[2] / 2])


def world_points() -> np.ndarray:
    """The road ahead and beside the path, and a wall that hides part of it (placed along the path)."""
    return drives.road_and_wall(GROUND_Z - ORIGIN[2]) @ rot(0.0, 0.0, 0.4).T + ORIGIN


# ---------------------------------------------------------------- writing a sequence


def write_calibration(folder) -> None:
    folder.mkdir(parents=True)
    (folder / "perspective.txt").write_text(
        drives.cam_to_cam(K, WIDTH, HEIGHT, {i: (-BASELINE * i, R_RECT[i]) for i in (0, 1)}))
    fisheye = rigid(Q, T0 + [0.0, 1.0, 0.0])
    (folder / "calib_cam_to_pose.txt").write_text("".join(
        f"image_{i:02d}: {numbers((CAM_TO_POSE.get(i, fisheye))[:3])}\n" for i in range(4)))
    (folder / "calib_cam_to_velo.txt").write_text(numbers(CAM0_TO_VELO[:3]) + "\n")


def opencv_matrix(tag: str, M, dt: str = "d") -> str:
    M = np.asarray(M)
    return (f'<{tag} type_id="opencv-matrix"><rows>{M.shape[0]}</rows><cols>{M.shape[1]}</cols><dt>{dt}</dt>'
            f"<data>{numbers(M)}</data></{tag}>")


# the official template: corners at +-0.5 in the box's own frame
CORNERS = np.array([[0.5, 0.5, 0.5], [0.5, 0.5, -0.5], [0.5, -0.5, 0.5], [0.5, -0.5, -0.5],
                    [-0.5, 0.5, -0.5], [-0.5, 0.5, 0.5], [-0.5, -0.5, -0.5], [-0.5, -0.5, 0.5]])
FACES = np.array([[0, 2, 1], [1, 2, 3], [4, 6, 5], [5, 6, 7], [0, 1, 5], [5, 1, 4], [2, 7, 3], [3, 7, 6],
                  [0, 5, 2], [2, 5, 7], [1, 3, 4], [4, 3, 6]])


def box_element(n: int, semantic: int, label: str, instance: int, box, lwh, timestamp: int, window) -> str:
    transform = box.copy()
    transform[:3, :3] = box[:3, :3] @ np.diag(lwh)
    return (f"<object{n}>{opencv_matrix('transform', transform)}{opencv_matrix('vertices', CORNERS, 'f')}"
            f"{opencv_matrix('faces', FACES, 'u')}<index>{n - 1}</index><label>{label}</label>"
            f"<category>vehicle</category><level>1</level><semanticId>{semantic}</semanticId>"
            f"<instanceId>{instance}</instanceId><timestamp>{timestamp}</timestamp><dynamic>{int(timestamp >= 0)}"
            f"</dynamic><start_frame>{window[0]}</start_frame><end_frame>{window[1]}</end_frame></object{n}>")


def write_boxes(path, elements: list[str]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text('<?xml version="1.0"?>\n<opencv_storage>\n' + "\n".join(elements) + "\n</opencv_storage>\n")


def car_elements() -> list[str]:
    """The moving car at frames 1..6 (frame 3's box has no imported frame), the parked car written
    with a reflected transform (its width axis flipped), and a building (not a vehicle)."""
    moving = [box_element(k, 13, "car", 7, car_box(k), CAR_LWH, k, (0, 20)) for k in range(1, 7)]
    parked = box_element(7, 13, "car", 9, PARKED, np.array(PARKED_LWH) * [1.0, -1.0, 1.0], -1, (4, 20))
    building = box_element(8, 11, "building", 2, rigid(np.eye(3), ORIGIN + [20.0, 12.0, 3.0]), (10, 8, 6), -1,
                           (0, 20))
    return moving + [parked, building]


def write_sequence(root):
    """``root`` as KITTI-360's root holding one sequence; returns ``root``."""
    rng = np.random.default_rng(3)
    write_calibration(root / "calibration")
    images = root / "data_2d_raw" / SEQ
    scans = root / "data_3d_raw" / SEQ / "velodyne_points" / "data"
    poses = root / "data_poses" / SEQ
    for folder in (images / "image_00" / "data_rect", images / "image_01" / "data_rect", scans, poses):
        folder.mkdir(parents=True)
    pts = world_points()
    for k in range(N_FRAMES):
        name = f"{k:010d}"
        for i in (0, 1):
            write_image(images / f"image_{i:02d}" / "data_rect" / f"{name}.png",
                        rng.integers(0, 256, (HEIGHT, WIDTH, 3)).astype(np.float32) / 255.0)
        drives.write_velodyne(scans / f"{name}.bin", pts, world_from_velo(k))
    for i in (0, 1):
        (images / f"image_{i:02d}" / "timestamps.txt").write_text(
            drives.timestamps("2013-05-28 08:46", 2, 975522090, N_FRAMES))
    (poses / "poses.txt").write_text("".join(f"{k} {numbers(world_from_pose(k)[:3])}\n" for k in POSED))
    (poses / "cam0_to_world.txt").write_text("".join(f"{k} {numbers(world_from_camera(0, k))}\n" for k in POSED))
    write_boxes(root / "data_3d_bboxes" / "train" / f"{SEQ}.xml", car_elements())
    return root


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return write_sequence(tmp_path_factory.mktemp("kitti360"))


@pytest.fixture(scope="module")
def package(root, tmp_path_factory):
    return drives.imported(["import", "kitti-360", str(root), "--sequence", SEQ], tmp_path_factory)


# ---------------------------------------------------------------- round trip


def test_poses_come_back_and_the_frame_without_a_pose_is_left_out(package):
    assert [c.name for c in package.cameras] == ["image_00", "image_01"]
    assert package.source["frame_names"] == [f"{k:010d}" for k in POSED]
    assert package.source["frames_without_pose"] == 1
    assert package.source["frames_without_pose_first"] == [f"{UNPOSED:010d}"]
    drives.assert_cameras(package, lambda camera, fi: world_from_camera(int(camera[-2:]), POSED[fi]),
                          lambda camera: K + [[0, 0, 0.5], [0, 0, 0.5], [0, 0, 0]], TOL_M)
    expected = [103_651_234 * k / 1e9 for k in POSED]
    assert np.allclose([f.timestamp for f in package.frames], expected, rtol=0, atol=1e-9)
    assert main(["validate", str(package.root)]) == 0


def test_poses_txt_with_the_rig_gives_the_same_cameras(root, tmp_path):
    """Without cam0_to_world.txt the system poses are composed with calib_cam_to_pose and R_rect_00."""
    import shutil

    copy = tmp_path / "root"
    shutil.copytree(root, copy)
    (copy / "data_poses" / SEQ / "cam0_to_world.txt").unlink()
    seq = read_kitti360(copy, SEQ)
    assert seq.source.notes["poses"] == "poses.txt"
    for row, i in zip(seq.source.grouped.table, (0, 1)):
        for v, k in zip(row, POSED):
            assert np.abs(v.c2w - world_from_camera(i, k)).max() < TOL_M, (i, k)


def test_the_ground_is_the_lidar_road_and_the_world_metric(package):
    drives.assert_metric_ground(package, world_points()[:-drives.WALL_POINTS], 0.02)


def test_every_camera_gets_its_frames_scans_as_sparse_depth(root, package):
    folder = root / "data_3d_raw" / SEQ / "velodyne_points" / "data"

    def want(camera: str, fi: int) -> np.ndarray:
        i, k = int(camera[-2:]), POSED[fi]
        scan = np.fromfile(folder / f"{k:010d}.bin", "<f4").reshape(-1, 4)[:, :3]
        M = invert_rigid(world_from_camera(i, k)) @ world_from_velo(k)
        return drives.expected_depth(moved(M, scan.astype(np.float64)), K, WIDTH, HEIGHT)

    assert [c.name for c in package.cameras] == ["image_00", "image_01"]
    drives.assert_sparse_depth(package, want, rtol=1e-7)


def test_the_boxes_come_back_as_existing_actors(package):
    by_id = {a.id: a for a in package.actors}
    assert sorted(by_id) == ["car_7", "car_9"]
    car, parked = by_id["car_7"], by_id["car_9"]
    assert car.kind == "existing" and np.allclose(car.wlh, [CAR_LWH[1], CAR_LWH[0], CAR_LWH[2]], rtol=0, atol=1e-12)
    drives.assert_actor_poses(package, car, lambda fi: car_box(POSED[fi]) if POSED[fi] in (1, 2, 4, 5, 6) else None,
                              TOL_M)
    assert np.allclose(parked.wlh, [PARKED_LWH[1], PARKED_LWH[0], PARKED_LWH[2]], rtol=0, atol=1e-12)
    # parked in its window (frames 4 to 20): the reflected width axis flipped back
    drives.assert_actor_poses(package, parked, lambda fi: None if POSED[fi] < 4 else PARKED, TOL_M)


def test_the_right_camera_as_lateral_truth(root, tmp_path, capsys):
    out = tmp_path / "pkg"
    assert main(["import", "kitti-360", str(root), "--sequence", SEQ, "--out", str(out), "--lateral-truth",
                 "image_01", "--quiet"]) == 0
    m = load_manifest(out)
    assert [c.name for c in m.cameras] == ["image_00"]
    assert m.effects.lateral_offsets == [BASELINE]
    assert len(m.actors) == 2 and m.cameras[0].frames[0].depth is not None
    text = capsys.readouterr().out
    assert "image_01" in text and "1 frame(s) with images but no pose" in text


def test_one_camera_and_a_window(root, tmp_path):
    out = tmp_path / "pkg"
    assert main(["import", "kitti-360", str(root), "--sequence", SEQ, "--out", str(out), "--cameras", "1",
                 "--frames", "2:5", "--quiet"]) == 0
    m = load_manifest(out)
    assert [c.name for c in m.cameras] == ["image_01"]
    assert m.source["frame_names"] == [f"{k:010d}" for k in (2, 4, 5)]
    T = np.asarray(m.source["transform"])
    assert np.abs(invert_rigid(T) @ m.cameras[0].frames[1].camera_to_world - world_from_camera(1, 4)).max() < TOL_M
    assert main(["validate", str(out), "--allow-external-assets"]) == 0


def test_the_first_camera_named_is_the_packages_first(root, tmp_path):
    out = tmp_path / "pkg"
    assert main(["import", "kitti-360", str(root), "--sequence", SEQ, "--out", str(out), "--cameras", "1,0",
                 "--quiet"]) == 0
    m = load_manifest(out)
    assert [c.name for c in m.cameras] == ["image_01", "image_00"] and m.ground_truth["camera"] == "image_01"


# ---------------------------------------------------------------- the official loaders


def test_kitti360scripts_reads_the_same_poses_calibration_and_boxes(root, monkeypatch):
    pytest.importorskip("kitti360scripts")
    pytest.importorskip("skimage")
    import matplotlib
    from kitti360scripts.devkits.commons import loadCalibration
    from kitti360scripts.helpers import annotation
    from kitti360scripts.helpers.project import CameraPerspective

    seq = read_kitti360(root, SEQ)
    calib = root / "calibration"
    to_pose = loadCalibration.loadCalibrationCameraToPose(str(calib / "calib_cam_to_pose.txt"))
    cam_to_velo = loadCalibration.loadCalibrationRigid(str(calib / "calib_cam_to_velo.txt"))
    for row, i in zip(seq.source.grouped.table, (0, 1)):
        official = CameraPerspective(str(root), SEQ, i)
        assert np.allclose(seq.cameras[f"image_{i:02d}"].K - [[0, 0, 0.5], [0, 0, 0.5], [0, 0, 0]],
                           official.K[:3, :3], rtol=0, atol=1e-12)
        assert (official.width, official.height) == (WIDTH, HEIGHT)
        for v, k in zip(row, POSED):
            assert np.allclose(v.c2w, official.cam2world[k], rtol=0, atol=1e-9), (i, k)
        # kitti360Viewer3DRaw.loadExtrinsics and projectVeloToImage: the Velodyne into rectified camera i
        velo_to_cam = np.linalg.inv(cam_to_velo @ np.linalg.inv(to_pose["image_00"]) @ to_pose[f"image_{i:02d}"])
        assert np.allclose(seq.cameras[f"image_{i:02d}"].velo_to_camera, official.R_rect @ velo_to_cam, rtol=0,
                           atol=1e-12)
    # annotation.py's boxes: its world corners are ours
    monkeypatch.setattr(annotation.cm, "get_cmap", matplotlib.colormaps.get_cmap, raising=False)
    ours = {b.where: b for b in seq.boxes}
    for child in ET.parse(root / "data_3d_bboxes" / "train" / f"{SEQ}.xml").getroot():
        box = annotation.KITTI360Bbox3D()
        box.parseBbox(child)
        if child.tag not in ours:
            assert box.name == "building"
            continue
        b = ours[child.tag]
        corners = b.centre + (CORNERS * b.lwh) @ b.rotation.T
        assert np.allclose(np.sort(corners, axis=0), np.sort(box.vertices, axis=0), rtol=0, atol=1e-9), child.tag
        assert box.instanceId == b.key[1] and box.name == b.kind


# ---------------------------------------------------------------- bad input


def refused(root, tmp_path, capsys, *needles, args=()):
    drives.refused(["import", "kitti-360", str(root), "--sequence", SEQ, *args], tmp_path, capsys, *needles)


@pytest.fixture
def bad(tmp_path):
    return write_sequence(tmp_path / "root")


@pytest.mark.parametrize("file,key", [("perspective.txt", "P_rect_01"), ("perspective.txt", "R_rect_00"),
                                      ("calib_cam_to_pose.txt", "image_01")])
def test_calibration_with_the_wrong_field_count(bad, tmp_path, capsys, file, key):
    path = bad / "calibration" / file
    lines = [f"{line} 1.0" if line.startswith(f"{key}:") else line for line in path.read_text().splitlines()]
    path.write_text("\n".join(lines) + "\n")
    refused(bad, tmp_path, capsys, file, f": {key}: ", "numbers, got")


def test_camera_to_velodyne_with_the_wrong_field_count(bad, tmp_path, capsys):
    path = bad / "calibration" / "calib_cam_to_velo.txt"
    path.write_text(" ".join(path.read_text().split()[:11]) + "\n")
    refused(bad, tmp_path, capsys, "calib_cam_to_velo.txt", "line 1", "expected 12 numbers, got 11")


def test_pose_line_with_the_wrong_field_count(bad, tmp_path, capsys):
    path = bad / "data_poses" / SEQ / "cam0_to_world.txt"
    lines = path.read_text().splitlines()
    lines[4] = " ".join(lines[4].split()[:13])
    path.write_text("\n".join(lines) + "\n")
    refused(bad, tmp_path, capsys, "cam0_to_world.txt", "line 5", "expected 16 numbers, got 12")


def test_scan_count_not_the_image_count(bad, tmp_path, capsys):
    (bad / "data_3d_raw" / SEQ / "velodyne_points" / "data" / "0000000005.bin").unlink()
    refused(bad, tmp_path, capsys, "velodyne_points", "7 scans for 8 images", "0000000005")


def test_box_without_a_transform(bad, tmp_path, capsys):
    elements = car_elements()
    elements[1] = elements[1].replace(elements[1][elements[1].index("<transform"):
                                                  elements[1].index("</transform>") + len("</transform>")], "")
    write_boxes(bad / "data_3d_bboxes" / "train" / f"{SEQ}.xml", elements)
    refused(bad, tmp_path, capsys, f"{SEQ}.xml", "object2.transform", "missing")


def test_missing_sequence_folder(bad, tmp_path, capsys):
    refused(bad, tmp_path, capsys, "2013_05_28_drive_0009_sync", "--sequence", "no such sequence folder",
            args=("--sequence", "2013_05_28_drive_0009_sync"))


def test_no_frame_with_a_pose(bad, tmp_path, capsys):
    refused(bad, tmp_path, capsys, "cam0_to_world.txt", "no frame of image_00/data_rect has a pose",
            args=("--frames", "3"))


def test_fisheye_camera_refused(bad, tmp_path, capsys):
    refused(bad, tmp_path, capsys, "--cameras", "perspective cameras are 0, 1", args=("--cameras", "0,2"))


def test_an_image_of_another_size_than_its_camera_is_refused_naming_it(bad, tmp_path, capsys):
    """The first camera's images are read for the LiDAR's colours before the package checks them."""
    image = bad / "data_2d_raw" / SEQ / "image_00" / "data_rect" / "0000000001.png"
    write_image(image, np.zeros((HEIGHT, WIDTH - 1, 3), np.float32))
    refused(bad, tmp_path, capsys, "image_00/data_rect/0000000001.png", f"image is {WIDTH - 1}x{HEIGHT}",
            f"is {WIDTH}x{HEIGHT}")
