"""nuScenes scenes in (``symdrive import nuscenes``): a scene written in nuScenes' table format from
known geometry (an ego path along +x with roll and pitch, two cameras and the LiDAR each recording
at its own time, LiDAR returns at known world points, one annotated car over three samples) comes
back within float64 round-off; nuscenes-devkit reads the same tables to the same intrinsics, ego
poses, boxes and projected LiDAR depths; bad input exits 2 naming the file and the field and
writes nothing."""

from __future__ import annotations

import hashlib
import json
from dataclasses import replace

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.conventions import invert_rigid
from symdrive_core.importers.nuscenes import NuScenesConfig, read_nuscenes
from symdrive_core.io.images import read_image, write_image
from symdrive_core.rotations import matrix_to_quat
from symdrive_core.scene import load_manifest

from . import drives
from .drives import moved, rigid

VERSION, SCENE = "v1.0-mini", "scene-0061"
N_SAMPLES, WIDTH, HEIGHT = 4, 64, 36
T0 = 1532402927647951  # the first sample's time, microseconds
CAMERA_DELAY_US = {"CAM_FRONT": 12_000, "CAM_BACK": 37_000, "LIDAR_TOP": 0}  # after the sample's time
CAR_WLH = (1.9, 4.6, 1.5)
TOL_M = 1e-9  # round-off of global coordinates near 1e3 m at float64


def token(*parts) -> str:
    return hashlib.md5("/".join(map(str, parts)).encode()).hexdigest()


def rot(rx, ry, rz) -> np.ndarray:
    def axis(i, a):
        c, s = np.cos(a), np.sin(a)
        R = np.eye(3)
        j, k = [(1, 2), (0, 2), (0, 1)][i]
        R[j, j], R[j, k], R[k, j], R[k, k] = c, -s, s, c
        if i == 1:
            R[0, 2], R[2, 0] = s, -s
        return R
    return axis(2, rz) @ axis(1, ry) @ axis(0, rx)


# Where each sensor sits on the vehicle (x forward, y left, z up): OpenCV camera axes, the LiDAR's
# x to the right as nuScenes mounts it; each a little tilted.
CAM_AXES = {"CAM_FRONT": np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]),
            "CAM_BACK": np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])}
EGO_FROM = {"CAM_FRONT": rigid(CAM_AXES["CAM_FRONT"] @ rot(0.012, -0.004, 0.003), [1.70, 0.02, 1.51]),
            "CAM_BACK": rigid(CAM_AXES["CAM_BACK"] @ rot(-0.006, 0.009, -0.002), [0.05, -0.01, 1.57]),
            "LIDAR_TOP": rigid(rot(0.002, -0.003, -np.pi / 2), [0.94, 0.0, 1.84])}
K = {"CAM_FRONT": np.array([[40.0, 0.0, 31.7], [0.0, 41.0, 17.9], [0.0, 0.0, 1.0]]),
     "CAM_BACK": np.array([[28.0, 0.0, 32.2], [0.0, 28.5, 18.1], [0.0, 0.0, 1.0]])}


def time_us(k: int, channel: str) -> int:
    return T0 + 500_000 * k + CAMERA_DELAY_US[channel]


def world_from_ego(t_us: int) -> np.ndarray:
    """The known ego path: along +x at 8 m/s bending slightly left, with some roll and pitch."""
    t = (t_us - T0) * 1e-6
    return rigid(rot(0.01 * np.sin(3 * t), 0.008 * np.cos(2 * t), 0.05 * t), [411.3 + 8.0 * t, 1180.7 + 0.3 * t * t, 0.0])


def world_from_sensor(k: int, channel: str) -> np.ndarray:
    return world_from_ego(time_us(k, channel)) @ EGO_FROM[channel]


def car_box(k: int) -> np.ndarray:
    return rigid(rot(0.0, 0.0, 0.2 + 0.01 * k), [421.0 + 3.0 * k, 1183.0, CAR_WLH[2] / 2])


def world_points() -> np.ndarray:
    """The road around the path, a wall ahead and one behind."""
    x, y = np.meshgrid(np.arange(395.0, 450.0, 0.7), np.arange(1172.0, 1190.0, 0.6))
    road = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    wy, wz = np.meshgrid(np.arange(1176.0, 1186.0, 0.4), np.arange(0.2, 3.0, 0.3))
    walls = [np.stack([np.full(wy.size, wx), wy.ravel(), wz.ravel()], 1) for wx in (448.0, 398.0)]
    return np.concatenate([road, *walls])


# ---------------------------------------------------------------- writing a dataset


def quat(R) -> list[float]:
    return [float(v) for v in matrix_to_quat(R)]


def write_tables(root, tables: dict[str, list[dict]]) -> None:
    (root / VERSION).mkdir(parents=True, exist_ok=True)
    for name, records in tables.items():
        (root / VERSION / f"{name}.json").write_text(json.dumps(records, indent=1))


def read_table(root, name: str) -> list[dict]:
    return json.loads((root / VERSION / f"{name}.json").read_text())


def linked(records: list[dict]) -> list[dict]:
    for a, b in zip(records, records[1:]):
        a["next"], b["prev"] = b["token"], a["token"]
    return records


def write_dataset(root):
    """A nuScenes DATAROOT with one scene of ``N_SAMPLES`` keyframes (and a second scene)."""
    rng = np.random.default_rng(5)
    channels = ("CAM_FRONT", "CAM_BACK", "LIDAR_TOP")
    sensor = [{"token": token("sensor", c), "channel": c, "modality": "lidar" if c == "LIDAR_TOP" else "camera"}
              for c in channels]
    calibrated = [{"token": token("cs", c), "sensor_token": token("sensor", c),
                   "translation": EGO_FROM[c][:3, 3].tolist(), "rotation": quat(EGO_FROM[c][:3, :3]),
                   "camera_intrinsic": K[c].tolist() if c in K else []} for c in channels]
    scene_tok, log_tok = token("scene", SCENE), token("log")
    samples = linked([{"token": token("sample", k), "timestamp": time_us(k, "LIDAR_TOP"), "prev": "", "next": "",
                       "scene_token": scene_tok} for k in range(N_SAMPLES)])
    other = {"token": token("sample", "other"), "timestamp": T0 + 10**8, "prev": "", "next": "",
             "scene_token": token("scene", "other")}
    ego, data = [], {c: [] for c in channels}
    pts = world_points()
    for k in range(N_SAMPLES):
        for c in channels:
            t = time_us(k, c)
            ego.append({"token": token("ego", c, k), "timestamp": t, "rotation": quat(world_from_ego(t)[:3, :3]),
                        "translation": world_from_ego(t)[:3, 3].tolist()})
            folder = root / "samples" / c
            folder.mkdir(parents=True, exist_ok=True)
            name = f"n015-2018-07-24-11-22-45+0800__{c}__{t}"
            if c == "LIDAR_TOP":
                filename = f"samples/{c}/{name}.pcd.bin"
                local = moved(invert_rigid(world_from_sensor(k, c)), pts)
                near = local[np.linalg.norm(local, axis=1) < 45.0]
                rows = np.hstack([near, np.full((len(near), 1), 7.0), np.arange(len(near))[:, None] % 32])
                rows.astype("<f4").tofile(root / filename)
            else:
                filename = f"samples/{c}/{name}.jpg"
                write_image(root / filename, rng.integers(0, 256, (HEIGHT, WIDTH, 3)).astype(np.float32) / 255.0)
            lidar = c == "LIDAR_TOP"
            data[c].append({"token": token("sd", c, k), "sample_token": token("sample", k),
                            "ego_pose_token": token("ego", c, k), "calibrated_sensor_token": token("cs", c),
                            "timestamp": t, "fileformat": "pcd" if lidar else "jpg", "is_key_frame": True,
                            "height": 0 if lidar else HEIGHT, "width": 0 if lidar else WIDTH,
                            "filename": filename, "prev": "", "next": ""})
        # a sweep between keyframes: not a keyframe, not imported (its file is not even written)
        data["CAM_FRONT"].append({**data["CAM_FRONT"][-1], "token": token("sweep", k), "is_key_frame": False,
                                  "sample_token": token("sample", min(k + 1, N_SAMPLES - 1)),
                                  "filename": f"sweeps/CAM_FRONT/{k}.jpg"})
    categories = [{"token": token("category", n), "name": n, "description": ""}
                  for n in ("vehicle.car", "human.pedestrian.adult")]
    car, walker = token("instance", "car"), token("instance", "walker")
    anns = linked([{"token": token("ann", "car", k), "sample_token": token("sample", k), "instance_token": car,
                    "visibility_token": "4", "attribute_tokens": [],
                    "translation": car_box(k)[:3, 3].tolist(), "size": list(CAR_WLH),
                    "rotation": quat(car_box(k)[:3, :3]), "prev": "", "next": "", "num_lidar_pts": 12,
                    "num_radar_pts": 0} for k in range(1, N_SAMPLES)])
    anns.append({**anns[0], "token": token("ann", "walker"), "instance_token": walker, "sample_token": token("sample", 0),
                 "size": [0.6, 0.7, 1.75], "prev": "", "next": ""})
    instances = [{"token": car, "category_token": token("category", "vehicle.car"), "nbr_annotations": 3,
                  "first_annotation_token": anns[0]["token"], "last_annotation_token": anns[2]["token"]},
                 {"token": walker, "category_token": token("category", "human.pedestrian.adult"), "nbr_annotations": 1,
                  "first_annotation_token": anns[3]["token"], "last_annotation_token": anns[3]["token"]}]
    (root / "maps").mkdir()
    (root / "maps" / "mask.png").write_bytes(b"")  # the devkit checks the file is there; nothing reads it
    write_tables(root, {
        "scene": [{"token": scene_tok, "log_token": log_tok, "nbr_samples": N_SAMPLES, "name": SCENE,
                   "first_sample_token": samples[0]["token"], "last_sample_token": samples[-1]["token"],
                   "description": "a bend along +x"},
                  {"token": token("scene", "other"), "log_token": log_tok, "nbr_samples": 1, "name": "scene-0103",
                   "first_sample_token": other["token"], "last_sample_token": other["token"], "description": ""}],
        "sample": samples + [other],
        "sample_data": [r for c in channels for r in linked(data[c])],
        "ego_pose": ego, "calibrated_sensor": calibrated, "sensor": sensor,
        "log": [{"token": log_tok, "logfile": "n015-2018-07-24-11-22-45+0800", "vehicle": "n015",
                 "date_captured": "2018-07-24", "location": "singapore-onenorth"}],
        "map": [{"token": token("map"), "log_tokens": [log_tok], "category": "semantic_prior",
                 "filename": "maps/mask.png"}],
        "instance": instances, "category": categories, "sample_annotation": anns,
        "attribute": [{"token": token("attribute"), "name": "vehicle.moving", "description": ""}],
        "visibility": [{"token": "4", "level": "v80-100", "description": ""}],
    })
    return root


CAMERAS = "CAM_FRONT,CAM_BACK"


@pytest.fixture(scope="module")
def dataroot(tmp_path_factory):
    return write_dataset(tmp_path_factory.mktemp("nuscenes"))


@pytest.fixture(scope="module")
def package(dataroot, tmp_path_factory):
    return drives.imported(["import", "nuscenes", str(dataroot), "--version", VERSION, "--scene", SCENE, "--cameras",
                            CAMERAS], tmp_path_factory)


# ---------------------------------------------------------------- round trip


def test_each_image_has_its_own_times_pose(package):
    """A camera's pose is the ego pose at the image's own time composed with where it sits on the
    vehicle; its K is camera_intrinsic with pixel centres moved to +0.5."""
    assert [c.name for c in package.cameras] == ["CAM_FRONT", "CAM_BACK"]  # the order asked for
    drives.assert_cameras(package, lambda camera, k: world_from_sensor(k, camera),
                          lambda camera: K[camera] + [[0, 0, 0.5], [0, 0, 0.5], [0, 0, 0]], TOL_M)
    assert package.source["frame_names"] == [token("sample", k) for k in range(N_SAMPLES)]
    # a frame's time is its earliest image's, in seconds since the first sample
    assert np.allclose([f.timestamp for f in package.frames], [0.5 * k + 0.012 for k in range(N_SAMPLES)],
                       rtol=0, atol=1e-12)
    assert package.source["nuscenes"]["location"] == "singapore-onenorth"
    assert package.source["nuscenes"]["time_origin_us"] == T0


def test_the_ground_is_the_lidar_road_and_the_world_metric(package):
    x, y = np.meshgrid(np.arange(395.0, 450.0, 0.7), np.arange(1172.0, 1190.0, 0.6))
    road = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    drives.assert_metric_ground(package, road, 0.03)  # the camera path's term moves it by the ego's roll and pitch


def scan_of(root, k: int) -> np.ndarray:
    (path,) = (root / "samples" / "LIDAR_TOP").glob(f"*__{time_us(k, 'LIDAR_TOP')}.pcd.bin")
    return np.fromfile(path, "<f4").reshape(-1, 5)[:, :3].astype(np.float64)


def camera_from_lidar(k: int, channel: str) -> np.ndarray:
    """The sweep through the LiDAR's pose at its time and the camera's at the image's."""
    return invert_rigid(world_from_sensor(k, channel)) @ world_from_sensor(k, "LIDAR_TOP")


def test_every_camera_gets_the_sweep_as_sparse_depth(dataroot, package):
    def want(channel: str, k: int) -> np.ndarray:
        return drives.expected_depth(moved(camera_from_lidar(k, channel), scan_of(dataroot, k)), K[channel],
                                     WIDTH, HEIGHT)

    drives.assert_sparse_depth(package, want, rtol=1e-6)


def test_the_lidar_points_are_the_first_cameras_returns_coloured_there(dataroot):
    config = replace(NuScenesConfig(), cameras=("CAM_FRONT", "CAM_BACK"), lidar_points=10**6)  # every return kept
    d = read_nuscenes(dataroot, SCENE, config)
    scan = scan_of(dataroot, 0)
    col, row, seen = drives.landing(moved(camera_from_lidar(0, "CAM_FRONT"), scan), K["CAM_FRONT"], WIDTH, HEIGHT)
    n = int(seen.sum())
    assert n > 100
    assert np.abs(d.source.points[:n] - moved(world_from_sensor(0, "LIDAR_TOP"), scan[seen])).max() < TOL_M
    (image,) = (dataroot / "samples" / "CAM_FRONT").glob(f"*__{time_us(0, 'CAM_FRONT')}.jpg")
    rgb = read_image(image, channels=3)
    assert np.array_equal(d.source.colors[:n], rgb[row[seen].astype(int), col[seen].astype(int)])


def test_the_annotated_car_comes_back_as_an_existing_actor(package):
    (car,) = package.actors  # the pedestrian is not a vehicle
    assert car.id == "car_0" and car.kind == "existing" and car.splats is None
    assert package.source["nuscenes"]["instances"] == {"car_0": token("instance", "car")}
    assert np.allclose(car.wlh, CAR_WLH, rtol=0, atol=1e-12)
    drives.assert_actor_poses(package, car, lambda k: None if k == 0 else car_box(k), TOL_M)


def test_the_package_validates_with_both_cameras(package):
    assert main(["validate", str(package.root)]) == 0


def test_one_camera(dataroot, tmp_path):
    out = tmp_path / "pkg"
    assert main(["import", "nuscenes", str(dataroot), "--scene", SCENE, "--cameras", "CAM_BACK", "--out",
                 str(out), "--quiet"]) == 0
    m = load_manifest(out)
    assert [c.name for c in m.cameras] == ["CAM_BACK"] and m.source["frame_names"][1] == token("sample", 1)
    T = np.asarray(m.source["transform"])
    assert np.abs(invert_rigid(T) @ m.cameras[0].frames[2].camera_to_world - world_from_sensor(2, "CAM_BACK")).max() \
        < TOL_M
    assert len(m.actors) == 1


# ---------------------------------------------------------------- nuscenes-devkit as the oracle


def test_the_devkit_reads_the_same_tables_to_the_same_scene(dataroot, package):
    nuscenes = pytest.importorskip("nuscenes.nuscenes")
    nusc = nuscenes.NuScenes(version=VERSION, dataroot=str(dataroot), verbose=False)
    explorer = nuscenes.NuScenesExplorer(nusc)
    T = np.asarray(package.source["transform"])
    sample = nusc.get("sample", nusc.scene[0]["first_sample_token"])
    compared = 0
    for k in range(N_SAMPLES):
        for cam in package.cameras:
            sd = nusc.get("sample_data", sample["data"][cam.name])
            cf = cam.frames[k]
            _, boxes, intrinsic = nusc.get_sample_data(sd["token"])
            assert np.allclose(cf.K - [[0, 0, 0.5], [0, 0, 0.5], [0, 0, 0]], intrinsic, rtol=0, atol=1e-12)
            pose = nusc.get("ego_pose", sd["ego_pose_token"])
            cs = nusc.get("calibrated_sensor", sd["calibrated_sensor_token"])
            c2w = _devkit_rigid(pose) @ _devkit_rigid(cs)
            assert np.abs(invert_rigid(T) @ cf.camera_to_world - c2w).max() < TOL_M
            # the devkit's boxes in the camera's frame: the actor's pose seen from the camera
            car = package.actors[0].poses[k]
            for box in (b for b in boxes if b.name == "vehicle.car"):
                compared += 1
                in_camera = invert_rigid(cf.camera_to_world) @ car.matrix()
                assert np.abs(in_camera[:3, 3] - box.center).max() < TOL_M
                assert np.abs(in_camera[:3, :3] - box.rotation_matrix).max() < 1e-12
                assert np.allclose(box.wlh, CAR_WLH)
            # the devkit's projection of the sweep: each pixel's nearest return is the depth map's
            uv, depths, _ = explorer.map_pointcloud_to_image(sample["data"]["LIDAR_TOP"], sd["token"], min_dist=0.5)
            check = _comparable(uv)
            nearest = np.full((HEIGHT, WIDTH), np.inf)
            np.minimum.at(nearest, (np.floor(uv[1] + 0.5).astype(int), np.floor(uv[0] + 0.5).astype(int)), depths)
            got = read_image(package.resolve(cf.depth))[:, :, 0]
            check &= np.isfinite(nearest)
            assert check.sum() > 200
            assert np.allclose(got[check], nearest[check], rtol=1e-5, atol=0), (cam.name, k)
        if sample["next"]:
            sample = nusc.get("sample", sample["next"])
    assert compared >= 3  # the car in front of CAM_FRONT in samples 1 to 3


def _comparable(uv: np.ndarray) -> np.ndarray:
    """The pixels [H, W] whose nearest return the devkit's projection settles: away from the
    image's 1-pixel rim (where it drops returns within a pixel) and from pixels a return lands
    within 1e-3 px of the edge of (its float32 arithmetic may put it in the neighbour)."""
    u, v = uv[0] + 0.5, uv[1] + 0.5  # package pixel coordinates
    fu, fv = u - np.floor(u), v - np.floor(v)
    edge = np.minimum.reduce([fu, 1 - fu, fv, 1 - fv]) < 1e-3
    ok = np.zeros((HEIGHT, WIDTH), bool)
    ok[2:-2, 2:-2] = True
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            ok[np.clip(np.floor(v[edge]).astype(int) + dr, 0, HEIGHT - 1),
               np.clip(np.floor(u[edge]).astype(int) + dc, 0, WIDTH - 1)] = False
    return ok


def _devkit_rigid(record: dict) -> np.ndarray:
    from pyquaternion import Quaternion

    return rigid(Quaternion(record["rotation"]).rotation_matrix, record["translation"])


# ---------------------------------------------------------------- bad input


def refused(root, tmp_path, capsys, *needles, args=("--cameras", CAMERAS)):
    drives.refused(["import", "nuscenes", str(root), "--version", VERSION, "--scene", SCENE, *args], tmp_path, capsys,
                   *needles)


@pytest.fixture
def bad(tmp_path):
    return write_dataset(tmp_path / "dataroot")


def edit(root, table: str, tok: str, **fields) -> None:
    records = read_table(root, table)
    for r in records:
        if r["token"] == tok:
            r.update(fields)
    write_tables(root, {table: records})


def test_a_token_that_points_nowhere(bad, tmp_path, capsys):
    edit(bad, "sample_data", token("sd", "CAM_BACK", 2), ego_pose_token="0" * 32)
    refused(bad, tmp_path, capsys, "sample_data.json", f"[{token('sd', 'CAM_BACK', 2)}].ego_pose_token",
            "points nowhere", "ego_pose.json")


def test_an_annotation_of_a_sample_that_is_nowhere(bad, tmp_path, capsys):
    edit(bad, "sample_annotation", token("ann", "car", 2), sample_token="0" * 32)
    refused(bad, tmp_path, capsys, "sample_annotation.json", f"[{token('ann', 'car', 2)}].sample_token",
            "points nowhere", "sample.json")


@pytest.mark.parametrize("size", [[-1.9, 4.6, 1.5], [1.9, 4.6e6, 1.5], [1.9, 0.0, 1.5]])
def test_one_box_of_a_size_no_vehicle_has(bad, tmp_path, capsys, size):
    edit(bad, "sample_annotation", token("ann", "car", 2), size=size)
    refused(bad, tmp_path, capsys, "sample_annotation.json", f"[{token('ann', 'car', 2)}].size",
            "w, l, h must lie in (0, ")


def test_a_number_that_is_not_finite_is_named(bad, tmp_path, capsys):
    edit(bad, "ego_pose", token("ego", "CAM_FRONT", 1), translation=[float("nan"), 0.0, 0.0])
    refused(bad, tmp_path, capsys, "ego_pose.json", f"[{token('ego', 'CAM_FRONT', 1)}].translation",
            "expected 3 numbers (x, y, z in metres), got nan")


def test_vehicles_are_named_in_order_of_first_appearance(tmp_path):
    root = write_dataset(tmp_path / "dataroot")
    anns, instances = read_table(root, "sample_annotation"), read_table(root, "instance")
    late = {**anns[1], "token": token("ann", "late"), "instance_token": token("instance", "late"), "prev": "",
            "next": "", "translation": (np.asarray(anns[1]["translation"]) + [0.0, 4.0, 0.0]).tolist()}
    instances.append({**instances[0], "token": token("instance", "late"), "nbr_annotations": 1,
                      "first_annotation_token": late["token"], "last_annotation_token": late["token"]})
    write_tables(root, {"sample_annotation": [late, *anns], "instance": instances})  # listed first, seen later
    out = tmp_path / "pkg"
    assert main(["import", "nuscenes", str(root), "--scene", SCENE, "--cameras", CAMERAS, "--out", str(out),
                 "--quiet"]) == 0
    assert load_manifest(out).source["nuscenes"]["instances"] == {"car_0": token("instance", "car"),
                                                                  "car_1": token("instance", "late")}


@pytest.mark.parametrize("name", ["../outside.jpg", "/etc/hostname", "samples/../../outside.jpg"])
def test_a_file_name_leading_out_of_the_dataroot_is_refused_not_read(bad, tmp_path, capsys, name):
    (bad.parent / "outside.jpg").write_bytes(b"not read")
    sd = token("sd", "CAM_FRONT", 1)
    edit(bad, "sample_data", sd, filename=name)
    refused(bad, tmp_path, capsys, "sample_data.json", f"[{sd}].filename", "outside DATAROOT")


def test_a_missing_table(bad, tmp_path, capsys):
    (bad / VERSION / "calibrated_sensor.json").unlink()
    refused(bad, tmp_path, capsys, "calibrated_sensor.json", "table not found")


def test_a_quaternion_of_the_wrong_length(bad, tmp_path, capsys):
    edit(bad, "ego_pose", token("ego", "CAM_FRONT", 1), rotation=[1.0, 0.0, 0.0])
    refused(bad, tmp_path, capsys, "ego_pose.json", f"[{token('ego', 'CAM_FRONT', 1)}].rotation",
            "expected 4 numbers (a quaternion w, x, y, z), got 3")


def test_an_unknown_scene_lists_the_scenes(dataroot, tmp_path, capsys):
    out = tmp_path / "pkg"
    rc = main(["import", "nuscenes", str(dataroot), "--scene", "scene-9999", "--out", str(out), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert "scene.json" in err and "--scene" in err and "scene-0061, scene-0103" in err, err
    assert not out.exists()


def test_a_channel_the_scene_lacks(dataroot, tmp_path, capsys):
    refused(dataroot, tmp_path, capsys, "sample_data.json", "--cameras", "no keyframe of CAM_FRONT_RIGHT",
            "has: CAM_BACK, CAM_FRONT, LIDAR_TOP", args=())  # the default: all six


def test_a_file_name_holding_a_nul_byte_is_refused_naming_the_field(bad, tmp_path, capsys):
    sd = token("sd", "CAM_FRONT", 1)
    edit(bad, "sample_data", sd, filename="samples/CAM_FRONT/a\u0000b.jpg")
    refused(bad, tmp_path, capsys, "sample_data.json", f"[{sd}].filename", "NUL byte")
