"""``symdrive sim`` on an imported package: no road truth (the corridor), no actors, its own
frame rate, the recorded images left outside the package."""

import json

import pytest

from symdrive_core.cli import main
from symdrive_core.io.ply import write_splats

from ..importers.demo_formats import CAMERA_HEIGHT, demo_world, link_images, write_colmap
from .conftest import DEMO

pytest.importorskip("pycolmap")


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    """The demo street through COLMAP (a random similarity of its world) at 15 frames/s."""
    tmp = tmp_path_factory.mktemp("imported")
    world = demo_world(seed=5)
    model = write_colmap(world, tmp / "sparse")
    link_images(world, tmp / "images")
    write_splats(tmp / "trained.ply", world.splats)
    pkg = tmp / "package"
    assert main(["import", "colmap", str(model), "--images", str(tmp / "images"), "--splats", str(tmp / "trained.ply"),
                 "--out", str(pkg), "--camera-height", str(CAMERA_HEIGHT), "--fps", "15", "--quiet"]) == 0
    return pkg


def _sim(package, out, *args):
    assert main(["sim", str(package), "--no-video", "--quiet", "--out", str(out), *args]) == 0
    return json.loads((out / "report.json").read_text())


@pytest.mark.parametrize("agent,extra", [("replay", ["--size", "16x9"]), ("idm", ["--no-render"])])
def test_replay_and_idm_complete_on_an_imported_drive(imported, tmp_path, agent, extra):
    report = _sim(imported, tmp_path, "--agent", agent, *extra)
    native = _sim(DEMO, tmp_path / "native", "--agent", agent, "--no-render")
    assert report["drivable_area"] == {"source": "corridor", "lanes": 1, "lane_width_m": 7.0, "half_width_m": 3.5}
    assert native["drivable_area"]["source"] == "ground_truth.road"
    assert report["dt"] == pytest.approx(1 / 15)
    # The import's metric scale (from the camera height) gives back the native route's length.
    assert report["route_length_m"] == pytest.approx(native["route_length_m"], rel=0.01)
    episode = report["episodes"][0]
    assert episode["end_reason"] == "route_end", episode["end_detail"]
    s = episode["scores"]
    assert s["no_collision"] == 1.0 and s["drivable_area_compliance"] == 1.0 and s["route_completion"] > 0.95


def test_cut_in_leaves_a_one_lane_corridor(imported, tmp_path):
    """Without lane truth there is no neighbouring lane to change into: the scripted lane change
    leaves the corridor, and the episode says so."""
    episode = _sim(imported, tmp_path, "--agent", "cut-in", "--no-render")["episodes"][0]
    assert episode["end_reason"] == "off_road" and episode["scores"]["drivable_area_compliance"] == 0.0
