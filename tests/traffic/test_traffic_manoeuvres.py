"""Scripted manoeuvres through TraCI with real SUMO: the chosen vehicle acts, the others react."""

import json

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.scene import load_manifest
from tests.traffic.scenes import write_package, write_pool

FRAME_DT = 0.1
ROAD = {"centerline": [[500.0, 200.0, 0.0], [800.0, 200.0, 0.0]], "lanes": 2, "lane_width": 3.5}
RIGHT, LEFT = 200.0 - 1.75, 200.0 + 1.75
AT = 1.0
AT_FRAME = 10


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("manoeuvres")
    return write_package(root / "pkg", n_frames=80, road=ROAD), write_pool(root / "pool")


@pytest.fixture(scope="module")
def base(scene, tmp_path_factory):
    """The same traffic without manoeuvres: identical up to the moment a manoeuvre starts."""
    return _run(scene, tmp_path_factory.mktemp("base"))


def _in_right_lane_mid_road(m, frame=AT_FRAME, need_left_follower=False):
    """Id of a vehicle in the right lane near the middle of the road at ``frame``."""
    for a in sorted(m.actors, key=lambda a: abs(_xy(a)[frame, 0] - 650.0) if a.poses[frame] else np.inf):
        if a.poses[frame] is None or abs(_xy(a)[frame, 1] - RIGHT) > 0.02:
            continue
        if not need_left_follower or any(
                b.poses[frame] is not None and abs(_xy(b)[frame, 1] - LEFT) < 0.02
                and 5.0 < _xy(a)[frame, 0] - _xy(b)[frame, 0] < 15.0 for b in m.actors):
            return a.id
    raise AssertionError("no suitable vehicle in the test traffic")


def _run(scene, tmp_path, spec=None, name="out"):
    pkg, pool = scene
    args = ["traffic", str(pkg), "--density", "40", "--seconds", "20", "--seed", "2", "--assets", str(pool),
            "--out", str(tmp_path / name)]
    if spec is not None:
        (tmp_path / f"{name}.json").write_text(json.dumps({"manoeuvres": [spec]}))
        args += ["--manoeuvre", str(tmp_path / f"{name}.json")]
    assert main(args) == 0
    return load_manifest(tmp_path / name)


def _xy(actor) -> np.ndarray:
    return np.array([np.nan * np.ones(2) if p is None else p.translation[:2] for p in actor.poses])


def _speed(actor) -> np.ndarray:
    return np.linalg.norm(np.diff(_xy(actor), axis=0), axis=1) / FRAME_DT


def _follower(m, actor, frame):
    """Nearest vehicle behind ``actor`` in its lane at ``frame``."""
    x, y = _xy(actor)[frame]
    behind = [(x - _xy(a)[frame, 0], a) for a in m.actors
              if a.id != actor.id and a.poses[frame] is not None and abs(_xy(a)[frame, 1] - y) < 0.5
              and _xy(a)[frame, 0] < x]
    return min(behind, key=lambda b: b[0])[1]


def test_hard_brake_stops_the_vehicle_and_its_follower_reacts(scene, base, tmp_path):
    m = _run(scene, tmp_path, {"kind": "hard_brake", "vehicle": {"near": [650.0, RIGHT]}, "at": AT,
                               "deceleration": 8.0, "hold": 3.0}, name="brake")
    log = m.ground_truth["traffic"]["manoeuvres"][0]
    braker = m.actor(log["vehicle"])
    v = _speed(braker)
    start = AT_FRAME
    assert v[start - 2] > 10.0 and np.nanmin(v[start:start + 40]) < 0.1
    decel = -np.diff(v[start:start + 25]) / FRAME_DT
    assert np.nanmax(decel) == pytest.approx(8.0, abs=0.8)  # commanded rate, not the type's 4.5 m/s^2
    follower = _follower(m, braker, start)
    assert np.nanmin(_speed(follower)[start:]) < np.nanmin(_speed(base.actor(follower.id))[start:]) - 3.0


def test_aggressive_lane_change_moves_one_lane_left(scene, base, tmp_path):
    m = _run(scene, tmp_path, {"kind": "lane_change", "vehicle": _in_right_lane_mid_road(base), "at": AT,
                               "direction": "left", "aggressive": True, "duration": 1.5})
    log = m.ground_truth["traffic"]["manoeuvres"][0]
    y = _xy(m.actor(log["vehicle"]))[:, 1]
    assert y[AT_FRAME - 1] == pytest.approx(RIGHT, abs=0.02) and "finished" in log
    done = int(round(log["finished"] / FRAME_DT))
    assert y[done] == pytest.approx(LEFT, abs=0.1)
    lateral_speed = np.abs(np.diff(y)) / FRAME_DT
    assert np.nanmax(lateral_speed) == pytest.approx(3.5 / 1.5, rel=0.15)


def test_cut_in_lands_just_ahead_and_the_cut_off_vehicle_brakes(scene, base, tmp_path):
    cutter_id = _in_right_lane_mid_road(base, need_left_follower=True)
    m = _run(scene, tmp_path, {"kind": "cut_in", "vehicle": cutter_id, "at": AT,
                               "direction": "left", "gap": 5.0, "duration": 1.5}, name="cut")
    log = m.ground_truth["traffic"]["manoeuvres"][0]
    cutter, victim = m.actor(log["vehicle"]), m.actor(log["cut_off"])
    assert log["gap_at_change_m"] == pytest.approx(5.0, abs=0.6)
    done = int(round(log["finished"] / FRAME_DT))
    (cx, cy), (vx, vy) = _xy(cutter)[done], _xy(victim)[done]
    assert cy == pytest.approx(LEFT, abs=0.1) and vy == pytest.approx(LEFT, abs=0.1) and cx > vx
    begin = int(round(log["change_requested"] / FRAME_DT))
    assert np.nanmin(_speed(victim)[begin:]) < np.nanmin(_speed(base.actor(victim.id))[begin:]) - 1.0


def test_manoeuvre_of_an_absent_vehicle_is_a_clear_error(scene, tmp_path, capsys):
    pkg, pool = scene
    (tmp_path / "spec.json").write_text(json.dumps({"manoeuvres": [
        {"kind": "hard_brake", "vehicle": "nobody", "at": 1.0}]}))
    rc = main(["traffic", str(pkg), "--density", "40", "--seconds", "20", "--assets", str(pool),
               "--manoeuvre", str(tmp_path / "spec.json"), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 2 and "'nobody' is not on the road at 1 s" in err and not (tmp_path / "out").exists()
