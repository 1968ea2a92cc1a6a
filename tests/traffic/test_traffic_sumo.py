"""``symdrive traffic`` end to end with real SUMO on small roads: packages, geometry, degenerate inputs."""

import json
import re

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.scene import check_files, load_manifest
from symdrive_core.scene.poses import yaw_of
from symdrive_core.scene.road import project_onto, road_from_json
from symdrive_core.traffic.sumo_run import SumoError, run_tool
from tests.traffic.scenes import CAR, VAN, curved_road, write_asset, write_package, write_pool

FAR = (10_000.0, -5_000.0)  # far from the origin: any net offset left unmapped would show


@pytest.fixture
def pool(tmp_path):
    return write_pool(tmp_path / "pool")


def _traffic(capsys, *args):
    try:  # a value argparse refuses exits, one found after parsing returns
        rc = main(["traffic", *map(str, args)])
    except SystemExit as exc:
        rc = exc.code
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_traffic_package_on_a_curved_road(tmp_path, pool, capsys):
    pkg = write_package(tmp_path / "pkg", n_frames=30, road=curved_road(FAR))
    rc, out, _ = _traffic(capsys, pkg, "--density", 35, "--seconds", 12, "--seed", 4, "--assets", pool,
                          "--out", tmp_path / "out")
    assert rc == 0
    m = load_manifest(tmp_path / "out")
    check_files(m)
    assert len(m.actors) >= 10 and all(a.kind == "inserted" for a in m.actors)
    assert {tuple(a.wlh) for a in m.actors} <= {CAR, VAN}
    gap = float(re.search(r"minimum gap: ([0-9.]+) m", out).group(1))
    assert gap == pytest.approx(m.ground_truth["traffic"]["gaps"]["min_gap_m"], abs=1e-3) and "overlaps: none" in out

    road = road_from_json(m.ground_truth["road"], m.path)
    line = road.centerline[:, :2]
    lateral, centre_z, heading_err = [], [], []
    for a in m.actors:
        present = [p for p in a.poses if p is not None]
        xy = np.array([p.translation[:2] for p in present])
        lateral += list(project_onto(line, xy)[0])
        centre_z += list(np.array([p.translation[2] for p in present]) - road.ground_height(xy) - a.wlh[2] / 2)
        motion = np.diff(xy, axis=0)
        moving = np.linalg.norm(motion, axis=1) > 0.3
        yaw = np.array([yaw_of(p.rotation) for p in present[:-1]])
        motion_yaw = np.arctan2(motion[:, 1], motion[:, 0])
        heading_err += list(np.abs(np.angle(np.exp(1j * (yaw - motion_yaw))))[moving])
    lateral = np.array(lateral)
    # box centres on the lane centres (+-1.75 m) except during lane changes
    off_lane = np.minimum(np.abs(lateral - 1.75), np.abs(lateral + 1.75))
    assert np.mean(off_lane < 0.02) > 0.9
    np.testing.assert_allclose(centre_z, 0.0, atol=1e-6)  # standing on the sloped road
    assert np.median(heading_err) < np.radians(1.0) and np.max(heading_err) < np.radians(10.0)


def test_same_seed_gives_the_same_traffic(tmp_path, pool, capsys):
    pkg = write_package(tmp_path / "pkg", n_frames=10, road=curved_road(length=120.0))
    runs = []
    for name in ("a", "b"):
        assert _traffic(capsys, pkg, "--density", 30, "--seconds", 5, "--seed", 7, "--assets", pool,
                        "--out", tmp_path / name)[0] == 0
        d = json.loads((tmp_path / name / "manifest.json").read_text())
        d["ground_truth"]["traffic"].pop("sumo_seconds")
        runs.append(d)
    assert runs[0] == runs[1] and runs[0]["actors"]


def test_zero_density_gives_a_valid_package_without_actors(tmp_path, capsys):
    pkg = write_package(tmp_path / "pkg", road=curved_road(length=80.0))
    rc, out, _ = _traffic(capsys, pkg, "--density", 0, "--seconds", 3, "--out", tmp_path / "out")
    assert rc == 0 and "0 vehicles" in out and "no frame has two vehicles" in out
    assert load_manifest(tmp_path / "out").actors == []


def test_very_short_road_holds_at_most_one_vehicle_per_lane(tmp_path, capsys):
    pool = write_pool(tmp_path / "pool", sizes=(CAR,))
    pkg = write_package(tmp_path / "pkg")
    rc, out, _ = _traffic(capsys, pkg, "--road", "straight:8", "--density", 500, "--seconds", 4, "--assets", pool,
                          "--out", tmp_path / "out")
    assert rc == 0
    m = load_manifest(tmp_path / "out")
    assert 1 <= len(m.actors) <= 4  # two lanes, one car each at the start, maybe one inflow each


def test_vehicle_longer_than_the_road_is_a_clear_error(tmp_path, capsys):
    pool = tmp_path / "pool"
    write_asset(pool / "truck", (2.5, 12.0, 3.5))
    pkg = write_package(tmp_path / "pkg")
    rc, _, err = _traffic(capsys, pkg, "--road", "straight:10", "--density", 20, "--seconds", 3, "--assets", pool,
                          "--out", tmp_path / "out")
    assert rc == 2 and "12 m long, the road only 10 m" in err and not (tmp_path / "out").exists()


def test_speed_zero_gives_standing_traffic(tmp_path, pool, capsys):
    pkg = write_package(tmp_path / "pkg", n_frames=10, road=curved_road(length=150.0))
    rc, out, _ = _traffic(capsys, pkg, "--density", 40, "--seconds", 6, "--speed", 0, "--assets", pool,
                          "--out", tmp_path / "out")
    assert rc == 0 and "overlaps: none" in out
    m = load_manifest(tmp_path / "out")
    assert len(m.actors) >= 8
    for a in m.actors:
        t = np.array([p.translation for p in a.poses])
        np.testing.assert_allclose(t, t[:1].repeat(len(t), 0), atol=1e-9)


@pytest.mark.parametrize("args,message", [
    (["--density", 10, "--seconds", 1], "--seconds must cover the package's frames"),
    (["--density", -1, "--seconds", 5], "argument --density: must be a finite number, 0 or more"),
    (["--density", 10, "--seconds", 5, "--speed", -3], "argument --speed: must be a finite number, 0 or more"),
])
def test_bad_settings_are_refused(tmp_path, pool, capsys, args, message):
    pkg = write_package(tmp_path / "pkg", road=curved_road(length=80.0))
    rc, _, err = _traffic(capsys, pkg, *args, "--assets", pool)
    assert rc == 2 and message in err


def test_package_without_a_road_asks_for_one(tmp_path, pool, capsys):
    pkg = write_package(tmp_path / "pkg")
    rc, _, err = _traffic(capsys, pkg, "--density", 10, "--seconds", 5, "--assets", pool)
    assert rc == 2 and "ground_truth.road" in err and "--road" in err


def test_output_may_not_replace_the_source(tmp_path, pool, capsys):
    pkg = write_package(tmp_path / "pkg", road=curved_road(length=80.0))
    rc, _, err = _traffic(capsys, pkg, "--density", 10, "--seconds", 5, "--assets", pool, "--out", pkg)
    assert rc == 2 and "replace the source package" in err and (pkg / "manifest.json").exists()


def test_sumo_run_that_overruns_its_limit_is_stopped(tmp_path):
    with pytest.raises(SumoError, match="did not finish within"):
        run_tool("sumo", ["--help"], timeout=1e-4, cwd=tmp_path)
