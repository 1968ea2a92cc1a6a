"""Bad tracks are reported by actor and frame, not silently fitted: a box jumping 10 m in one
frame, a track that leaves the images and comes back, an id reused by two cars (its box jumps and
changes size); boxes that jitter by a tracker's decimetres are not."""

from __future__ import annotations

import json

import numpy as np
import pytest

from symdrive_core.eval.poses import jittered
from symdrive_core.rotations import quat_from_yaw
from symdrive_core.scene import Camera, CameraFrame, Frame, Manifest, Pose, load_manifest
from tests.importers.test_tracks import K, kitti_label, level_camera, run, write_json

FRAMES = 12
CAR = {"w": 1.8, "l": 4.5, "h": 1.5}


@pytest.fixture
def pkg(tmp_path):
    """12 frames at 10 Hz, the camera driving along +X at 0.5 m per frame."""
    root = tmp_path / "pkg"
    root.mkdir()
    cams = [level_camera(0.5 * i, 0.0, 0.0) for i in range(FRAMES)]
    m = Manifest("street", [Frame(i, 0.1 * i) for i in range(FRAMES)],
                 [Camera("front", 64, 48, [CameraFrame(K, c, np.linalg.inv(c)) for c in cams])], [], root=root,
                 path=root / "manifest.json")
    m.save()
    return root


def ahead(f: int) -> list[float]:
    """A car 15 m ahead at frame 0 driving at 10 m/s, in the camera's view throughout."""
    return [15.0 + 1.0 * f, 0.5, 0.75]


def boxes(centres: dict[int, list[float]]) -> list[dict]:
    return [{"frame": f, "centre": c, "yaw": 0.0} for f, c in sorted(centres.items())]


def imported(pkg, tmp_path, capsys, tracks) -> tuple[list[tuple], str]:
    """Import ``tracks`` (JSON, world frame): ((actor, frame, kind) reported, the warning line)."""
    assert run(pkg, write_json(tmp_path / "t.json", "world", tracks)) == 0
    notes = load_manifest(pkg).source["tracks"]
    assert notes["actors"] == sorted(t["id"] for t in tracks)
    return [(r["actor"], r["frame"], r["kind"]) for r in notes["reported"]], capsys.readouterr().err


def test_a_box_jumping_10_m_in_one_frame_is_reported(pkg, tmp_path, capsys):
    centres = {f: ahead(f) for f in range(FRAMES)}
    centres[6] = [centres[6][0] + 10.0, 0.5, 0.75]
    reported, err = imported(pkg, tmp_path, capsys, [{"id": "car_1", **CAR, "boxes": boxes(centres)}])
    assert reported == [("car_1", 6, "jump"), ("car_1", 7, "jump")]  # out and back
    assert err.startswith("warning: 2 tracked box(es)") and "car_1 frame 6" in err and "car_1 frame 7" in err


def test_a_track_that_leaves_the_images_and_comes_back_is_reported(pkg, tmp_path, capsys):
    gone = {f: ahead(f) for f in range(FRAMES) if not 3 <= f <= 5}  # no box in frames 3-5
    behind = {f: ahead(f) if not 3 <= f <= 5 else [0.5 * f - 8.0, 0.5, 0.75] for f in range(FRAMES)}
    tracks = [{"id": "gone", **CAR, "boxes": boxes(gone)},
              {"id": "behind", **CAR, "boxes": boxes(behind)}]  # boxes behind the camera in frames 3-5
    reported, err = imported(pkg, tmp_path, capsys, tracks)
    assert ("gone", 6, "reenters") in reported and ("behind", 6, "reenters") in reported
    assert {a for a, _, _ in reported} == {"gone", "behind"} and "back in view after frames 3-5" in err


def test_an_id_reused_by_two_cars_is_reported(pkg, tmp_path, capsys):
    """KITTI labels of track 4: a car until frame 5, then a van in the next lane under the same id."""
    m = load_manifest(pkg)
    lines = []
    for f in range(FRAMES):
        c2w = m.cameras[0].frames[f].camera_to_world
        if f < 6:
            lines.append(kitti_label(f, 4, "Car", c2w, ahead(f), 0.0, (1.8, 4.5, 1.5)))
        else:
            lines.append(kitti_label(f, 4, "Van", c2w, [12.0 + 0.8 * f, -3.0, 1.1], 0.0, (2.0, 5.6, 2.2)))
    path = tmp_path / "0004.txt"
    path.write_text("\n".join(lines) + "\n")
    assert run(pkg, path) == 0
    reported = [(r["actor"], r["frame"], r["kind"]) for r in load_manifest(pkg).source["tracks"]["reported"]]
    assert ("track_4", 6, "size") in reported and ("track_4", 6, "jump") in reported
    assert {f for _, f, _ in reported} == {6}
    assert "another vehicle under the same id" in capsys.readouterr().err


def test_a_trackers_jitter_is_not_reported(pkg, tmp_path, capsys):
    truth = [Pose(np.array(ahead(f)), quat_from_yaw(0.0)) for f in range(FRAMES)]
    noisy = jittered(truth, 0.2, np.radians(2.0), np.random.default_rng(0))
    tracks = [{"id": "car_1", **CAR, "boxes": [{"frame": f, "centre": p.translation.tolist(),
                                                "quaternion": p.rotation.tolist()} for f, p in enumerate(noisy)]}]
    reported, err = imported(pkg, tmp_path, capsys, tracks)
    assert reported == [] and err == ""
    assert json.loads((pkg / "manifest.json").read_text())["source"]["tracks"] == {"actors": ["car_1"], "reported": []}
