"""Demand placement, asset pools and the manoeuvre spec: validation without running SUMO."""

import json

import numpy as np
import pytest

from symdrive_core.errors import InputError
from symdrive_core.traffic.assets import asset_pool
from symdrive_core.traffic.demand import MIN_GAP_M, initial_positions
from symdrive_core.traffic.manoeuvre_spec import load_manoeuvres, parse_manoeuvres
from tests.traffic.scenes import CAR, VAN, write_asset, write_pool


@pytest.mark.parametrize("density", [5.0, 40.0, 1000.0])
def test_initial_positions_keep_the_minimum_gap_and_fit_the_lane(density):
    lengths = np.array([CAR[1], VAN[1], 12.0])
    placed = initial_positions(300.0, density, lengths, np.random.default_rng(1))
    fronts = np.array([f for f, _ in placed])
    rear_of_next = fronts[1:] - lengths[[k for _, k in placed[1:]]]
    assert np.all(rear_of_next - fronts[:-1] >= MIN_GAP_M - 1e-9)
    assert fronts[0] >= lengths[placed[0][1]] and fronts[-1] <= 300.0
    expected = min(density * 0.3, 300.0 / (MIN_GAP_M + lengths.mean()))
    assert 0.5 * expected <= len(placed) <= 1.5 * expected + 1


def test_zero_density_places_nobody():
    assert initial_positions(300.0, 0.0, np.array([4.5]), np.random.default_rng(0)) == []


def test_asset_pool_finds_nested_folders_once(tmp_path):
    write_pool(tmp_path / "pool")
    pool = asset_pool([tmp_path / "pool", tmp_path / "pool" / "vehicle1"])
    assert [tuple(a.wlh) for a in pool] == [CAR, VAN] and all(a.splats.exists() for a in pool)


def test_asset_without_sizes_or_files_is_refused(tmp_path):
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "wlh.json").write_text(json.dumps({"wlh": [1.8, 0, 1.5]}))
    with pytest.raises(InputError, match="wlh"):
        asset_pool([tmp_path])
    folder = write_asset(tmp_path / "empty", CAR)
    (folder / "splats.ply").unlink()
    with pytest.raises(InputError, match="neither a splat PLY nor a mesh"):
        asset_pool([folder])


def test_spec_fills_defaults(tmp_path):
    path = tmp_path / "spec.json"
    path.write_text(json.dumps({"manoeuvres": [
        {"kind": "hard_brake", "vehicle": "veh3", "at": 1.5},
        {"kind": "cut_in", "vehicle": {"near": [10, -1.75]}, "at": 0.5, "direction": "left", "gap": 4},
    ]}))
    brake, cut = load_manoeuvres(path)
    assert (brake.deceleration, brake.speed, brake.hold) == (7.0, 0.0, 2.0)
    assert cut.vehicle == (10.0, -1.75) and cut.gap == 4.0 and cut.duration == 1.5


@pytest.mark.parametrize("m,field,message", [
    ({"kind": "swerve", "vehicle": "a", "at": 1}, r"manoeuvres\[0\]\.kind", "expected one of"),
    ({"kind": "hard_brake", "at": 1}, r"manoeuvres\[0\]\.vehicle", "required"),
    ({"kind": "lane_change", "vehicle": "a", "at": 1, "direction": "up"}, r"manoeuvres\[0\]\.direction", "left or right"),
    ({"kind": "hard_brake", "vehicle": "a", "at": 1, "deceleration": 0}, r"manoeuvres\[0\]\.deceleration", "positive"),
    ({"kind": "hard_brake", "vehicle": "a", "at": 1, "gap": 3}, r"manoeuvres\[0\]", "unknown field"),
    ({"kind": "cut_in", "vehicle": {"near": [1]}, "at": 1, "direction": "left"}, r"manoeuvres\[0\]\.vehicle", "near"),
    ({"kind": "lane_change", "vehicle": "a", "at": "soon", "direction": "left"}, r"manoeuvres\[0\]\.at", "number"),
])
def test_bad_spec_names_the_field(m, field, message):
    with pytest.raises(InputError, match=rf"{field}: .*{message}"):
        parse_manoeuvres({"manoeuvres": [m]}, "spec.json")
