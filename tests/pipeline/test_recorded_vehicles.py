"""``symdrive run`` on a drive with a recorded vehicle: the default run fits it in its own frame
and renders it, an edit of it is inpainted where it exposes the street, and a scene without edits
plans no inpainting (no diffusion model)."""

import json
import shutil

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.io.images import read_image, read_mask
from symdrive_core.pipeline.plan import make_plan
from symdrive_core.scene import load_manifest
from tests.optim.moving_box import write_moving_box

# Removed at frames 0 and 1 the car uncovers wall no other frame saw; at frame 6 what it uncovers
# was seen by the frames around it, so there is nothing to inpaint.
REMOVED = [0, 1, 6]


@pytest.fixture(scope="module")
def reconstructed(moving_box, tmp_path_factory):
    """The moving box reconstructed (quick budget) and linked, as ``symdrive reconstruct`` leaves it."""
    root = tmp_path_factory.mktemp("box") / "pkg"
    shutil.copytree(moving_box[0], root)
    m = load_manifest(root)
    m.background_splats = "reconstruction/background.ply"
    m.actor("car_1").splats = "reconstruction/actors/car_1.ply"
    m.save()
    return root


def _edit(root, frames):
    """Remove the recorded car at ``frames`` (its recorded poses kept), as the add-on exports it."""
    m = load_manifest(root)
    car = m.actor("car_1")
    car.recorded_poses = list(car.poses)
    for f in frames:
        car.poses[f] = None
    m.save()
    return m


def _stages(out):
    return {s["name"]: s for s in json.loads((out / "report.json").read_text())["stages"]}


def test_without_edits_nothing_is_inpainted_and_no_model_loads(reconstructed):
    plan = make_plan(load_manifest(reconstructed))
    assert not plan.runs("inpaint") and "no recorded vehicle removed" in plan.stage("inpaint").reason
    assert not plan.needs_diffusion


def test_a_removed_car_is_inpainted_where_it_was(reconstructed, tmp_path):
    root = tmp_path / "edited"
    shutil.copytree(reconstructed, root)
    m = _edit(root, REMOVED)
    plan = make_plan(m)
    assert plan.runs("inpaint") and plan.stage("inpaint").frames == REMOVED and plan.needs_diffusion
    out = tmp_path / "out"
    assert main(["run", str(root), "--out", str(out), "--quiet"]) == 0
    assert _stages(out)["inpaint"]["frames_inpainted"] == 2
    for f in REMOVED[:2]:
        render = read_image(out / f"render/front/{f:06d}.png", channels=3)
        filled = read_image(out / f"inpaint/front/{f:06d}.png", channels=3)
        region = read_mask(out / f"inpaint/front/{f:06d}.region.png") > 0.5
        assert region.sum() > 50 and not (out / f"masks/front/car_1/{f:06d}.png").exists()
        assert np.array_equal(render[~region], filled[~region])  # only the unseen exposed pixels change
        assert np.abs(render[region] - filled[region]).mean() > 1e-3
    assert not (out / "inpaint/front/000006.png").exists()  # seen by its neighbours: nothing to fill
    assert not (out / "inpaint/front/000004.png").exists()  # the car is where it was recorded


def test_the_default_run_fits_and_renders_the_recorded_car(tmp_path):
    """A package with tracks and no reconstruction: ``symdrive run`` with no options."""
    root, *_ = write_moving_box(tmp_path / "pkg")
    out = tmp_path / "out"
    assert main(["run", str(root), "--out", str(out), "--quiet"]) == 0
    stages = _stages(out)
    assert stages["reconstruct"]["ran"] and stages["reconstruct"]["actors"]["car_1"] > 100
    assert stages["reconstruct"]["depth_weight"] == 0.0  # no sensor depth: the depth loss stays off
    assert (out / "reconstruction/actors/car_1.ply").exists()
    mask = read_mask(out / "masks/front/car_1/000008.png")
    assert (mask > 0.5).sum() > 100
    report = json.loads((out / "report.json").read_text())
    assert report["metrics"]["reconstruction"]["psnr_heldout"] > 20.0


def test_a_recorded_car_without_gaussians_stops_the_plan(reconstructed, tmp_path, capsys):
    """Background given, the car never fitted: one line naming the actor, exit 2."""
    m = load_manifest(reconstructed)
    m.actor("car_1").splats = None
    m.save(tmp_path / "manifest.json")
    (tmp_path / "reconstruction").symlink_to(reconstructed / "reconstruction")
    for folder in ("img",):
        (tmp_path / folder).symlink_to(reconstructed / folder)
    (tmp_path / "points.ply").symlink_to(reconstructed / "points.ply")
    assert main(["plan", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "car_1" in err[0] and "actors[0].assets" in err[0]


def test_the_shipped_traffic_street_plans_its_recorded_vehicles():
    """The shipped package with moving traffic: every file there, four recorded cars to fit in their
    own frames, and the truth of its edits readable."""
    from pathlib import Path

    from symdrive_core.scene import check_files
    from symdrive_core.scene.ground_truth import edit_truth, vehicle_masks

    root = Path(__file__).resolve().parents[2] / "symdrive_core" / "data" / "traffic_street"
    m = load_manifest(root)
    check_files(m)
    plan = make_plan(m)
    assert plan.runs("reconstruct") and plan.stage("reconstruct").actors == ["car_0", "car_1", "car_2", "car_3"]
    assert not plan.runs("inpaint") and not plan.needs_diffusion
    assert {e.kind for e in edit_truth(m)} == {"remove", "move", "retime"} and len(vehicle_masks(m)) == 24
