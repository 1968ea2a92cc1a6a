"""Tracked vehicles in (``symdrive import tracks``): boxes written in the world, the source frame,
a camera's coordinates and KITTI's labels come back as the world boxes they were made from, in
float64; bad input exits 2 with one line naming the file and the field and leaves the manifest
as it was."""

from __future__ import annotations

import json

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.rotations import quat_normalize, quat_to_matrix
from symdrive_core.scene import Actor, Camera, CameraFrame, Frame, Manifest, Pose, load_manifest
from symdrive_core.scene.visibility import box_corners_world, vehicle_local_box

FRAMES = 5
TOL = 1e-9
K = np.array([[60.0, 0.0, 32.0], [0.0, 60.0, 24.0], [0.0, 0.0, 1.0]])
SCALE = 0.37  # the source transform's scale: world metres per source unit


def rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def level_camera(x: float, y: float, heading: float, height: float = 1.6) -> np.ndarray:
    """OpenCV camera-to-world of a level camera looking along ``heading`` (camera -y = world up)."""
    f = np.array([np.cos(heading), np.sin(heading), 0.0])
    r = np.array([np.sin(heading), -np.cos(heading), 0.0])
    c2w = np.eye(4)
    c2w[:3, :3] = np.column_stack([r, [0.0, 0.0, -1.0], f])
    c2w[:3, 3] = [x, y, height]
    return c2w


def source_transform() -> np.ndarray:
    R = quat_to_matrix(quat_normalize(np.array([0.3, -0.5, 0.7, 0.2])))
    T = np.eye(4)
    T[:3, :3] = SCALE * R
    T[:3, 3] = [120.0, -40.0, 3.0]
    return T


def make_package(root, top_instance: int = 7):
    """5 frames, camera ``front`` driving a gentle bend, an existing and an inserted actor."""
    root.mkdir(parents=True, exist_ok=True)
    cams = [level_camera(4.0 * i, 0.2 * i * i, 0.05 * i) for i in range(FRAMES)]
    frames = [CameraFrame(K, c, np.linalg.inv(c)) for c in cams]
    actors = [Actor("parked", "existing", "actors/parked.ply", None, [Pose.identity()] * FRAMES,
                    np.array([1.8, 4.5, 1.5]), top_instance),
              Actor("ins", "inserted", None, "actors/ins.obj", [None] * FRAMES, None, 3)]
    m = Manifest("street", [Frame(i, 0.1 * i) for i in range(FRAMES)], [Camera("front", 64, 48, frames)], actors,
                 source={"transform": source_transform().tolist()}, root=root, path=root / "manifest.json")
    m.save()
    return root


@pytest.fixture
def pkg(tmp_path):
    return make_package(tmp_path / "pkg")


def vehicle_corners(centre, R, wlh) -> np.ndarray:
    """The 8 corners of a 3DRealCar box (X along l, Y along w, Z along h, centred)."""
    w, l, h = wlh
    local = np.array([[x, y, z] for x in (-l / 2, l / 2) for y in (-w / 2, w / 2) for z in (-h / 2, h / 2)])
    return local @ np.asarray(R).T + centre


def kitti_corners(loc, ry, h, w, l) -> np.ndarray:
    """KITTI devkit's ``computeBox3D``: corners in camera coordinates."""
    x = [l / 2, l / 2, -l / 2, -l / 2, l / 2, l / 2, -l / 2, -l / 2]
    y = [0, 0, 0, 0, -h, -h, -h, -h]
    z = [w / 2, -w / 2, -w / 2, w / 2, w / 2, -w / 2, -w / 2, w / 2]
    R = np.array([[np.cos(ry), 0, np.sin(ry)], [0, 1, 0], [-np.sin(ry), 0, np.cos(ry)]])
    return (R @ np.array([x, y, z])).T + loc


def to_world(T, points) -> np.ndarray:
    return np.asarray(points) @ T[:3, :3].T + T[:3, 3]


def assert_same_corners(a, b, tol=TOL):
    d = np.linalg.norm(a[:, None] - b[None], axis=2)
    assert d.min(1).max() < tol and d.min(0).max() < tol and len(set(d.argmin(1))) == 8, d.min(1).max()


def actor_corners(a: Actor, fi: int) -> np.ndarray:
    p = a.poses[fi]
    return box_corners_world(*vehicle_local_box(a.wlh), p.R, p.translation)


def write_json(path, frame, tracks):
    path.write_text(json.dumps({"frame": frame, "tracks": tracks}))
    return path


def run(*argv) -> int:
    return main(["import", "tracks", *map(str, argv)])


# ---------------------------------------------------------------- JSON frames


def test_world_boxes_come_back_as_existing_actors_after_the_largest_instance_id(pkg, tmp_path, capsys):
    tilt = quat_normalize(np.array([0.9, 0.05, -0.1, 0.4]))
    tracks = [{"id": "car_3", "w": 1.8, "l": 4.5, "h": 1.5,
               "boxes": [{"frame": 0, "centre": [10.0, 2.0, 0.75], "yaw": 0.3},
                         {"frame": 2, "centre": [12.5, 2.25, 0.76], "quaternion": tilt.tolist()}]},
              {"id": "van", "w": 2.0, "l": 5.2, "h": 2.1, "boxes": [{"frame": 4, "centre": [30.0, -3.0, 1.05],
                                                                     "yaw": -2.9}]}]
    assert run(pkg, write_json(tmp_path / "t.json", "world", tracks)) == 0
    out = capsys.readouterr().out.strip()
    assert len(out.splitlines()) == 1 and "2 tracks" in out and "3 boxes" in out and "0 boxes outside" in out
    m = load_manifest(pkg)
    assert [(a.id, a.kind, a.instance_id) for a in m.actors] == [
        ("parked", "existing", 7), ("ins", "inserted", 3), ("car_3", "existing", 8), ("van", "existing", 9)]
    car = m.actor("car_3")
    assert car.splats is None and car.mesh is None
    np.testing.assert_array_equal(car.wlh, [1.8, 4.5, 1.5])
    assert [p is None for p in car.poses] == [False, True, False, True, True]
    np.testing.assert_allclose(car.poses[0].translation, [10.0, 2.0, 0.75], atol=TOL)
    np.testing.assert_allclose(car.poses[0].R, rot_z(0.3), atol=TOL)
    np.testing.assert_allclose(car.poses[2].R, quat_to_matrix(tilt), atol=TOL)
    assert_same_corners(actor_corners(car, 0), vehicle_corners([10.0, 2.0, 0.75], rot_z(0.3), (1.8, 4.5, 1.5)))
    np.testing.assert_allclose(m.actor("van").poses[4].R, rot_z(-2.9), atol=TOL)


def test_source_boxes_move_and_scale_with_the_source_transform(pkg, tmp_path):
    T = source_transform()
    q = quat_normalize(np.array([0.2, 0.6, -0.3, 0.7]))
    boxes = [{"frame": 1, "centre": [3.0, -7.0, 11.0], "yaw": 1.1},
             {"frame": 3, "centre": [-2.0, 5.0, 0.5], "quaternion": q.tolist()}]
    wlh = (5.0, 12.0, 4.0)  # source units
    assert run(pkg, write_json(tmp_path / "t.json", "source",
                               [{"id": "bus", "w": wlh[0], "l": wlh[1], "h": wlh[2], "boxes": boxes}])) == 0
    bus = load_manifest(pkg).actor("bus")
    np.testing.assert_allclose(bus.wlh, SCALE * np.array(wlh), rtol=1e-12)
    for fi, R in ((1, rot_z(1.1)), (3, quat_to_matrix(q))):
        centre = next(b["centre"] for b in boxes if b["frame"] == fi)
        # the box's corners in the source frame, moved as points by the similarity
        assert_same_corners(actor_corners(bus, fi), to_world(T, vehicle_corners(centre, R, wlh)))


def test_camera_boxes_follow_kitti_bottom_centre_and_axes(pkg, tmp_path):
    m = load_manifest(pkg)
    ry = 0.4
    tilt = quat_normalize(np.array([0.95, 0.1, 0.2, -0.05]))
    boxes = [{"frame": 2, "centre": [1.5, 1.6, 12.0], "yaw": ry},
             {"frame": 3, "centre": [-2.0, 1.5, 9.0], "quaternion": tilt.tolist()}]
    assert run(pkg, write_json(tmp_path / "t.json", "camera",
                               [{"id": "car", "w": 1.7, "l": 4.2, "h": 1.4, "boxes": boxes}]), "--camera", "front") == 0
    car = load_manifest(pkg).actor("car")
    c2w = m.cameras[0].frames[2].camera_to_world
    assert_same_corners(actor_corners(car, 2), to_world(c2w, kitti_corners([1.5, 1.6, 12.0], ry, 1.4, 1.7, 4.2)))
    # corners are blind to a half turn about the length: the car's forward is KITTI's heading, its up the world's
    R = car.poses[2].R
    np.testing.assert_allclose(R[:, 0], c2w[:3, :3] @ [np.cos(ry), 0.0, -np.sin(ry)], atol=TOL)
    np.testing.assert_allclose(R[:, 2], [0.0, 0.0, 1.0], atol=TOL)
    # a quaternion turns KITTI's object axes: its corners are the devkit's template turned by it
    template = kitti_corners(np.zeros(3), 0.0, 1.4, 1.7, 4.2)
    expected = to_world(m.cameras[0].frames[3].camera_to_world, template @ quat_to_matrix(tilt).T + [-2.0, 1.5, 9.0])
    assert_same_corners(actor_corners(car, 3), expected)


# ---------------------------------------------------------------- KITTI


def kitti_label(frame, track, kind, c2w, centre, yaw, wlh) -> str:
    """A KITTI tracking line of a world box (centre, yaw about Z) seen by a level camera."""
    w, l, h = wlh
    w2c = np.linalg.inv(c2w)
    loc = to_world(w2c, np.asarray(centre) - [0.0, 0.0, h / 2])
    heading = w2c[:3, :3] @ rot_z(yaw)[:, 0]
    ry = np.arctan2(-heading[2], heading[0])
    values = [0, 0, -10, 100, 120, 150, 170, h, w, l, *loc, ry]
    return " ".join([str(frame), str(track), kind, *(repr(float(v)) for v in values)])


WORLD_BOXES = [  # (frame, centre, yaw): one car over four frames, seen from each frame's camera
    (0, [14.0, 1.5, 0.8], 0.2), (1, [17.0, 2.2, 0.8], 0.25), (2, [20.0, 3.1, 0.81], 0.31), (4, [26.0, 5.5, 0.82], 0.4)]
CAR = (1.75, 4.4, 1.6)


def kitti_file(path, m, frame_offset: int = 0, shift=np.zeros(3)):
    cams = m.cameras[0].frames
    lines = []
    for fi, centre, yaw in WORLD_BOXES:
        lines.append(kitti_label(fi + frame_offset, 3, "Car", cams[fi].camera_to_world, centre, yaw, CAR))
        lines.append(f"{fi + frame_offset} -1 DontCare -1 -1 -10 1 2 3 4 -1 -1 -1 -1000 -1000 -1000 -10")
    lines.append(kitti_label(1 + frame_offset, 8, "Pedestrian", cams[1].camera_to_world, [9.0, -2.0, 0.9], 0.0,
                             (0.6, 0.8, 1.8)))
    text = "\n".join(lines) + "\n"
    if shift.any():  # labels in rectified camera 0's frame, camera 2 sitting at ``shift`` in it
        text = "\n".join(_shifted(line, shift) for line in text.splitlines()) + "\n"
    path.write_text(text)
    return path


def _shifted(line: str, shift) -> str:
    words = line.split()
    words[13:16] = [repr(float(v) + float(s)) for v, s in zip(words[13:16], shift)]
    return " ".join(words)


def test_kitti_labels_give_back_the_world_boxes(pkg, tmp_path, capsys):
    m = load_manifest(pkg)
    labels = kitti_file(tmp_path / "0003.txt", m)
    assert run(pkg, labels) == 0
    out = capsys.readouterr().out
    assert "1 tracks" in out and "4 boxes" in out and "DontCare 4, Pedestrian 1" in out
    car = load_manifest(pkg).actor("track_3")
    assert car.kind == "existing" and car.instance_id == 8
    np.testing.assert_allclose(car.wlh, CAR, rtol=1e-15)
    assert car.poses[3] is None
    for (fi, centre, yaw), line in zip(WORLD_BOXES, labels.read_text().splitlines()[::2]):
        np.testing.assert_allclose(car.poses[fi].translation, centre, atol=TOL)
        np.testing.assert_allclose(car.poses[fi].R, rot_z(yaw), atol=TOL)
        world = vehicle_corners(centre, rot_z(yaw), CAR)
        assert_same_corners(actor_corners(car, fi), world)
        v = [float(x) for x in line.split()[10:17]]  # h w l x y z rotation_y
        devkit = to_world(m.cameras[0].frames[fi].camera_to_world, kitti_corners(v[3:6], v[6], v[0], v[1], v[2]))
        assert_same_corners(devkit, world)


def test_kitti_labels_keep_their_own_2d_boxes_by_track_and_frame(pkg, tmp_path):
    """The annotators' 2D boxes (``x1 y1 x2 y2``) come back by track, named as the import names
    its actors, and frame; what the types leave out has none."""
    from symdrive_core.importers.tracks import read_kitti_label_boxes

    labels = kitti_file(tmp_path / "0003.txt", load_manifest(pkg))
    boxes = read_kitti_label_boxes(labels)
    assert set(boxes) == {"track_3"} and set(boxes["track_3"]) == {fi for fi, _, _ in WORLD_BOXES}
    for box in boxes["track_3"].values():
        np.testing.assert_array_equal(box, [100, 120, 150, 170])  # kitti_label's x1 y1 x2 y2
    assert set(read_kitti_label_boxes(labels, ("Car", "Pedestrian"))) == {"track_3", "track_8"}


def test_kitti_calibration_moves_boxes_from_camera_0_into_camera_2(pkg, tmp_path):
    m = load_manifest(pkg)
    offset = np.array([-0.06, 0.002, 0.003])  # camera 2 in rectified camera 0's frame
    P2 = np.column_stack([K, -K @ offset])
    calib = tmp_path / "calib.txt"
    calib.write_text("P0: " + " ".join(["7e2", "0", "6e2", "0", "0", "7e2", "1.7e2", "0", "0", "0", "1", "0"])
                     + "\nP2: " + " ".join(repr(float(v)) for v in P2.ravel())
                     + "\nR_rect " + " ".join(map(str, np.eye(3).ravel())) + "\n")
    assert run(pkg, kitti_file(tmp_path / "0003.txt", m, shift=offset), "--calib", calib) == 0
    car = load_manifest(pkg).actor("track_3")
    for fi, centre, yaw in WORLD_BOXES:
        assert_same_corners(actor_corners(car, fi), vehicle_corners(centre, rot_z(yaw), CAR))


def test_frame_offset_and_boxes_outside_the_package_are_counted(pkg, tmp_path, capsys):
    m = load_manifest(pkg)
    labels = kitti_file(tmp_path / "labels.txt", m, frame_offset=10)
    c2w = m.cameras[0].frames[0].camera_to_world
    with labels.open("a") as f:  # a later box of track 3 and a track wholly after the package
        f.write(kitti_label(15, 3, "Car", c2w, [40.0, 1.0, 0.8], 0.0, CAR) + "\n")
        f.write(kitti_label(30, 5, "Van", c2w, [20.0, 1.0, 1.0], 0.0, (2.0, 5.0, 2.0)) + "\n")
    assert run(pkg, labels, "--frame-offset", 10, "--types", "Car,Van") == 0
    out = capsys.readouterr().out
    assert "1 tracks" in out and "4 boxes" in out and "2 boxes outside the package's frames 0..4" in out
    assert "1 tracks with none inside" in out
    car = load_manifest(pkg).actor("track_3")
    np.testing.assert_allclose(car.poses[2].translation, WORLD_BOXES[2][1], atol=TOL)
    assert [a.id for a in load_manifest(pkg).actors] == ["parked", "ins", "track_3"]


def test_kitti_size_is_the_tracks_median(pkg, tmp_path):
    c2w = load_manifest(pkg).cameras[0].frames[0].camera_to_world
    sizes = [(1.7, 4.3, 1.5), (1.9, 4.1, 1.4), (1.8, 4.6, 1.7)]
    (tmp_path / "l.txt").write_text("".join(kitti_label(i, 0, "Truck", c2w, [15.0, 0.0, 1.0], 0.0, s) + "\n"
                                            for i, s in enumerate(sizes)))
    assert run(pkg, tmp_path / "l.txt") == 0
    np.testing.assert_allclose(load_manifest(pkg).actor("track_0").wlh, [1.8, 4.3, 1.5], rtol=1e-15)


# ---------------------------------------------------------------- replacing


def test_replace_replaces_existing_actors_keeping_their_instance_id(pkg, tmp_path):
    tracks = [{"id": "parked", "w": 1.9, "l": 4.8, "h": 1.6, "boxes": [{"frame": 1, "centre": [5, 5, 0.8], "yaw": 0}]}]
    assert run(pkg, write_json(tmp_path / "t.json", "world", tracks), "--replace") == 0
    m = load_manifest(pkg)
    parked = m.actor("parked")
    assert (parked.kind, parked.instance_id, parked.splats) == ("existing", 7, None)
    assert [p is None for p in parked.poses] == [True, False, True, True, True]
    assert [a.id for a in m.actors] == ["parked", "ins"]


# ---------------------------------------------------------------- bad input


def good_track(**changes) -> dict:
    t = {"id": "car", "w": 1.8, "l": 4.5, "h": 1.5, "boxes": [{"frame": 0, "centre": [10.0, 0.0, 0.75], "yaw": 0.0},
                                                             {"frame": 1, "centre": [11.0, 0.0, 0.75], "yaw": 0.1}]}
    t.update(changes)
    return t


def box(**changes) -> dict:
    b = {"frame": 1, "centre": [11.0, 0.0, 0.75], "yaw": 0.1}
    b.update(changes)
    return {k: v for k, v in b.items() if v is not None}


BAD_JSON = [
    ("world", [good_track(w=0)], "tracks[0].w", "(0, 1000]"),
    ("world", [good_track(h=1001)], "tracks[0].h", "(0, 1000]"),
    ("world", [good_track(l="4")], "tracks[0].l", "finite number"),
    ("world", [good_track(boxes=[box(centre=[1.0, float("nan"), 0.0])])], "tracks[0].boxes[0].centre[1]", "finite"),
    ("world", [good_track(boxes=[box(yaw=float("inf"))])], "tracks[0].boxes[0].yaw", "finite"),
    ("world", [good_track(boxes=[box(centre=[2e7, 0.0, 0.0])])], "tracks[0].boxes[0].centre", "beyond"),
    ("world", [good_track(boxes=[box(yaw=None, quaternion=[0, 0, 0, 0])])], "tracks[0].boxes[0].quaternion", "zero"),
    ("world", [good_track(boxes=[box(quaternion=[1, 0, 0, 0])])], "tracks[0].boxes[0]", "one of yaw or quaternion"),
    ("world", [good_track(boxes=[box(), box()])], "tracks[0].boxes[1].frame", "frame 1 already"),
    ("world", [good_track(boxes=[])], "tracks[0].boxes", "no boxes"),
    ("world", [good_track(boxes=[box(frame=-1)])], "tracks[0].boxes[0].frame", "integer >= 0"),
    ("world", [good_track(boxes=[box(pitch=0.1)])], "tracks[0].boxes[0].pitch", "unknown field"),
    ("world", [good_track(id="../car")], "tracks[0].id", "'/'"),
    ("world", [good_track(id=".car")], "tracks[0].id", "start with '.'"),
    ("world", [good_track(), good_track()], "tracks[1].id", "duplicate track id"),
    ("world", [good_track(id="parked")], "tracks[0].id", "--replace"),
    ("world", [good_track(id="ins")], "tracks[0].id", "kind inserted"),
    ("lidar", [good_track()], "frame", "expected one of world, source, camera"),
    ("world", {"car": 1}, "tracks", "expected a list"),
]


def assert_refused(pkg, argv, capsys, *needles):
    before = (pkg / "manifest.json").read_bytes()
    assert run(pkg, *argv) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("symdrive import: error: "), err
    for needle in needles:
        assert needle in err, (needle, err)
    assert captured.out == ""
    assert (pkg / "manifest.json").read_bytes() == before
    assert [p.name for p in pkg.iterdir()] == ["manifest.json"]


@pytest.mark.parametrize("frame, tracks, field, says", BAD_JSON, ids=[f"{c[2]}-{c[3]}" for c in BAD_JSON])
def test_bad_json_is_refused_naming_file_and_field(pkg, tmp_path, capsys, frame, tracks, field, says):
    path = write_json(tmp_path / "t.json", frame, tracks)
    assert_refused(pkg, [path], capsys, f"{path}: {field}: ", says)


@pytest.mark.parametrize("text, field, says", [
    ('{"frame": "world"}', "tracks", "required field is missing"),
    ('{"frame": "world", "tracks": [], "extra": 1}', "extra", "unknown field"),
    ('{"frame": "world", "tracks": [', None, "not valid JSON"),
    ("[" * 100000 + "]" * 100000, None, "not valid JSON"),
])
def test_unreadable_json_is_refused(pkg, tmp_path, capsys, text, field, says):
    path = tmp_path / "t.json"
    path.write_text(text)
    assert_refused(pkg, [path], capsys, f"{path}: {field + ': ' if field else ''}{says}")


def label(**changes) -> str:
    fields = {"frame": "0", "track": "3", "type": "Car", "rest": "0 0 -10 1 2 3 4 1.5 1.8 4.5 1.0 1.6 12.0 0.1"}
    fields.update(changes)
    return " ".join(fields.values())


@pytest.mark.parametrize("line, says", [
    (label(rest="0 0 -10 1 2 3 4 1.5 1.8 4.5 1.0 1.6 12.0"), "expected 17 or 18 fields"),
    (label(rest="0 0 -10 1 2 3 4 1.5 1.8 4.5 1.0 nan 12.0 0.1"), "number 12 is nan, not a finite number"),
    (label(rest="0 0 -10 1 2 3 4 1.5 1.8 4.5 1.0 x 12.0 0.1"), "numbers"),
    (label(rest="0 0 -10 1 2 3 4 0 1.8 4.5 1.0 1.6 12.0 0.1"), "h, w, l must lie in (0, 1000]"),
    (label(rest="0 0 -10 1 2 3 4 1.5 1.8 4.5 1.0 1.6 3e7 0.1"), "beyond"),
    (label(frame="-2"), "frame: expected an integer >= 0"),
    (label(frame="1.5"), "frame: expected an integer"),
    (label(track="x"), "track_id: expected an integer"),
    (label(track="-1"), "track_id: expected an integer >= 0"),
    (label(), "track 3 has a box in frame 0 already (line 1)"),
])
def test_malformed_kitti_lines_are_refused_naming_the_line(pkg, tmp_path, capsys, line, says):
    path = tmp_path / "0000.txt"
    path.write_text(label() + "\n\n" + line + "\n")
    assert_refused(pkg, [path], capsys, f"{path}: line 3: ", says)


def test_more_actors_than_instance_ids_are_refused(tmp_path, capsys):
    pkg = make_package(tmp_path / "full", top_instance=65535)
    path = write_json(tmp_path / "t.json", "world", [good_track()])
    assert_refused(pkg, [path], capsys, f"{path}: tracks: ", "exceed the 65535 ids")


def test_options_that_do_not_fit_the_file_are_refused(pkg, tmp_path, capsys):
    world = write_json(tmp_path / "t.json", "world", [good_track()])
    assert_refused(pkg, [world, "--types", "Car"], capsys, f"{world}: --types: ", "KITTI labels")
    assert_refused(pkg, [world, "--camera", "front"], capsys, f"{world}: frame: ", "--camera")
    camera = write_json(tmp_path / "c.json", "camera", [good_track()])
    assert_refused(pkg, [camera, "--camera", "rear"], capsys, "manifest.json: --camera: ", "no camera named 'rear'")
    other = tmp_path / "tracks.csv"
    other.write_text("")
    assert_refused(pkg, [other], capsys, f"{other}: --format: ", "suffix")
    labels = tmp_path / "l.txt"
    labels.write_text(label() + "\n")
    assert_refused(pkg, [labels, "--calib", tmp_path / "none.txt"], capsys, "none.txt: --calib: ", "not found")
    (tmp_path / "calib.txt").write_text("P0: 1 0 0 0 0 1 0 0 0 0 1 0\n")
    assert_refused(pkg, [labels, "--calib", tmp_path / "calib.txt"], capsys, "calib.txt: P2: ", "no P2 line")


def test_source_frame_needs_the_packages_source_transform(tmp_path, capsys):
    pkg = make_package(tmp_path / "pkg")
    data = json.loads((pkg / "manifest.json").read_text())
    del data["source"]
    (pkg / "manifest.json").write_text(json.dumps(data))
    path = write_json(tmp_path / "t.json", "source", [good_track()])
    assert_refused(pkg, [path], capsys, "manifest.json: source.transform: ", "no source transform")
