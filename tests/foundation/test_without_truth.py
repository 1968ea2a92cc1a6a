"""Every command on a package without ground truth, as an import writes one: no
``ground_truth`` block at all (no lateral or insertion truth, no road, no held-out split).

A command that does not need truth does its work; one that does (a scorer, traffic's road)
stops before any work with one line naming the manifest and the field, and exit status 2.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.io.ply import write_splats
from symdrive_core.io.points import write_points
from tests.conftest import manifest_dict, random_gaussians, write_recorded_images
from tests.traffic.scenes import CAR, write_pool


@pytest.fixture
def bare_package(tmp_path):
    """``bare_package(images=True, lateral=(-1.0, 1.0))``: three 32x24 frames, background splats
    and points, one actor, the recorded images when asked: everything but ground truth."""

    def _make(images: bool = True, lateral=(-1.0, 1.0)):
        root = tmp_path / "pkg"
        root.mkdir()
        d = manifest_dict(n_frames=3, lateral=lateral)
        background = random_gaussians(200, 0, 1, (10, 0, 1), 3.0)
        write_splats(root / "background.ply", background)
        write_splats(root / "car_0.ply", random_gaussians(50, 1, 10, spread=0.8))
        rng = np.random.default_rng(0)
        write_points(root / "points.ply", rng.normal([10, 0, 1], 3.0, (300, 3)), rng.uniform(0, 1, (300, 3)))
        d["background"]["points"] = "points.ply"
        if images:
            write_recorded_images(root, d, background)
        assert "ground_truth" not in d
        (root / "manifest.json").write_text(json.dumps(d))
        return root

    return _make


def refused(capsys, package, field: str) -> str:
    """The one stderr line of a command that exited 2: it names the manifest and ``field``."""
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert f"{package / 'manifest.json'}: {field}: " in lines[0], lines[0]
    return lines[0]


RESTORE = ["--offsets", "1", "--steps", "1", "--n-start", "0", "--samples", "1", "--quiet"]


def test_validate_plan_and_render_do_their_work(bare_package, tmp_path, capsys):
    pkg = bare_package()
    assert main(["validate", str(pkg)]) == 0
    assert main(["plan", str(pkg), "--json", str(tmp_path / "plan.json")]) == 0
    stages = {s["name"]: s for s in json.loads((tmp_path / "plan.json").read_text())["stages"]}
    assert stages["render"]["run"] and stages["restore"]["run"]
    assert main(["render", str(pkg), "--camera", "front", "--frames", "0,2", "--out", str(tmp_path / "r"),
                 "--quiet"]) == 0
    assert sorted(p.name for p in (tmp_path / "r").rglob("*.png")) == ["000000.png", "000002.png"]


def test_reconstruct_fits_and_lateral_scoring_is_refused_before_the_fit(bare_package, tmp_path, capsys):
    pkg = bare_package()
    assert main(["reconstruct", str(pkg), "--iters", "2", "--out", str(tmp_path / "rec"), "--quiet"]) == 0
    assert (tmp_path / "rec" / "background.ply").exists()
    capsys.readouterr()
    assert main(["reconstruct", str(pkg), "--iters", "2", "--out", str(tmp_path / "lat"), "--lateral",
                 "--quiet"]) == 2
    assert "drop --lateral" in refused(capsys, pkg, "ground_truth.lateral")
    assert not (tmp_path / "lat").exists()


def test_pairs_with_cycles_and_training_on_them(bare_package, tmp_path):
    pkg = bare_package()
    pairs = tmp_path / "pairs.safetensors"
    assert main(["make-pairs", str(pkg), "--offsets", "1", "--cycle", "1", "--cycle-iters", "2",
                 "--out", str(pairs), "--quiet"]) == 0
    assert pairs.stat().st_size > 0
    assert main(["train-restorer", str(pairs), "--out", str(tmp_path / "train"), "--iters", "2", "--batch", "1",
                 "--crop", "16", "--quiet"]) == 0
    assert (tmp_path / "train" / "restorer.safetensors").stat().st_size > 0


def test_restore_without_scoring_writes_the_views(bare_package, tmp_path):
    pkg = bare_package()
    out = tmp_path / "out"
    assert main(["restore", str(pkg), "--out", str(out), *RESTORE]) == 0
    index = json.loads((out / "restored.json").read_text())
    assert len(index["views"]) == 3 * 2
    assert all((out / v["image"]).exists() for v in index["views"])


@pytest.mark.parametrize("flags,field,hint", [
    (["--evaluate"], "ground_truth.lateral", "drop --evaluate"),
    (["--evaluate", "--refine", "--refine-iters", "1"], "ground_truth.lateral", "drop --evaluate"),
    (["--evaluate", "--frames", "1"], "ground_truth.lateral", "drop --evaluate"),
])
def test_restore_scoring_is_one_line(bare_package, tmp_path, capsys, flags, field, hint):
    pkg = bare_package()
    assert main(["restore", str(pkg), "--out", str(tmp_path / "out"), *RESTORE, *flags]) == 2
    assert hint in refused(capsys, pkg, field)
    assert not (tmp_path / "out").exists()


def test_restore_refine_without_evaluate_is_one_line(bare_package, tmp_path, capsys):
    pkg = bare_package()
    assert main(["restore", str(pkg), "--out", str(tmp_path / "out"), *RESTORE, "--refine"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "--refine: needs --evaluate" in lines[0]
    assert not (tmp_path / "out").exists()


def test_traffic_needs_a_road_given_on_the_command_line(bare_package, tmp_path, capsys):
    pkg = bare_package()
    assert main(["traffic", str(pkg), "--density", "1", "--seconds", "1", "--out", str(tmp_path / "t")]) == 2
    assert "--road" in refused(capsys, pkg, "ground_truth.road")
    assert not (tmp_path / "t").exists()
    pool = write_pool(tmp_path / "pool", sizes=(CAR,))
    assert main(["traffic", str(pkg), "--road", "straight:60", "--density", "20", "--seconds", "2",
                 "--assets", str(pool), "--out", str(tmp_path / "t"), "--quiet"]) == 0
    assert json.loads((tmp_path / "t" / "manifest.json").read_text())["ground_truth"]["road"]


def test_insert_renders_and_insert_eval_is_one_line(bare_package, tmp_path, capsys):
    pkg = bare_package()
    assert main(["insert", str(pkg), "--actor", "car_0", "--out", str(tmp_path / "ins"), "--quiet"]) == 0
    assert len(list((tmp_path / "ins").rglob("*.png"))) >= 3
    capsys.readouterr()
    assert main(["insert-eval", str(pkg), "--gaussians", str(pkg / "background.ply"), "--steps", "1",
                 "--samples", "1", "--json", str(tmp_path / "eval.json"), "--quiet"]) == 2
    assert "symdrive insert" in refused(capsys, pkg, "ground_truth.insertion")
    assert not (tmp_path / "eval.json").exists()


def test_run_restores_and_scores_what_it_can(bare_package, tmp_path):
    pkg = bare_package()
    out = tmp_path / "out"
    assert main(["run", str(pkg), "--out", str(out), "--no-refine", "--no-adapt", "--quiet"]) == 0
    report = json.loads((out / "report.json").read_text())
    ran = {s["name"] for s in report["stages"] if s["ran"]}
    assert {"render", "restore", "evaluate"} <= ran
    assert "lateral" not in report["metrics"] and "insertion" not in report["metrics"]
    assert len(list((out / "restore").rglob("*.png"))) == 3 * 2


def test_batch_runs_a_package_without_truth(bare_package, tmp_path):
    pkg = bare_package(images=False, lateral=())
    assert main(["batch", str(pkg), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    reports = list((tmp_path / "out").rglob("report.json"))
    assert len(reports) == 1
    assert {s["name"] for s in json.loads(reports[0].read_text())["stages"] if s["ran"]} >= {"render"}


def test_bench_measures_the_renderer_on_recorded_frames(bare_package, tmp_path, capsys):
    pkg = bare_package()
    assert main(["bench", "accuracy-time", "--package", str(pkg), "--out", str(tmp_path / "b"), "--quick",
                 "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "left out restorer knobs: no lateral ground truth" in out
    assert "left out fine-tune knobs: no insertion ground truth" in out
    rows = json.loads((tmp_path / "b" / "accuracy_time.json").read_text())["rows"]
    assert {r["knob"] for r in rows} >= {"antialiasing", "precision"}


def test_bench_with_nothing_to_score_is_one_line(bare_package, tmp_path, capsys):
    pkg = bare_package(images=False)
    assert main(["bench", "accuracy-time", "--package", str(pkg), "--out", str(tmp_path / "b"), "--quiet"]) == 2
    assert "nothing to score" in refused(capsys, pkg, "ground_truth")
    assert not (tmp_path / "b").exists()


@pytest.mark.parametrize("agent,extra", [("replay", ["--size", "16x12"]), ("idm", ["--no-render"]),
                                         ("idm", ["--no-render", "--traffic", "sumo", "--vehicles", "2"])])
def test_sim_drives_the_corridor(bare_package, tmp_path, agent, extra):
    pkg = bare_package()
    out = tmp_path / "sim"
    assert main(["sim", str(pkg), "--agent", agent, *extra, "--no-video", "--quiet", "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["drivable_area"]["source"] == "corridor"
    assert len(report["episodes"]) == 1


def test_import_lidar_adds_depth(bare_package, tmp_path):
    """Scans are points in the camera frame (identity sensor-to-camera), 5 to 15 m ahead."""
    pkg = bare_package()
    scans = tmp_path / "scans"
    scans.mkdir()
    rng = np.random.default_rng(1)
    for i in range(3):
        z = rng.uniform(5, 15, 200)
        pts = np.stack([rng.uniform(-0.5, 0.5, 200) * z, rng.uniform(-0.35, 0.35, 200) * z, z], 1)
        np.savez(scans / f"{i}.npz", points=pts.astype(np.float32))
    calib = tmp_path / "calib.txt"
    calib.write_text(" ".join(str(v) for v in np.eye(4).ravel()))
    assert main(["import", "lidar", str(pkg), str(scans), "--sensor-to-camera", str(calib), "--quiet"]) == 0
    frames = json.loads((pkg / "manifest.json").read_text())["cameras"][0]["frames"]
    assert all((pkg / f["depth"]).exists() for f in frames)


def test_restore_evaluate_on_frames_the_truth_leaves_out_is_one_line(bare_package, tmp_path, capsys):
    """Lateral truth of frame 0 only: scoring frame 1 is refused as missing truth, naming the frame."""
    pkg = bare_package()
    d = json.loads((pkg / "manifest.json").read_text())
    d["ground_truth"] = {"lateral": [{"offset_m": 1.0, "frames": {"0": d["cameras"][0]["frames"][0]["image"]}}]}
    (pkg / "manifest.json").write_text(json.dumps(d))
    assert main(["restore", str(pkg), "--out", str(tmp_path / "out"), *RESTORE, "--evaluate", "--frames", "1"]) == 2
    assert "no lateral ground truth for frame(s) 1 (restore --evaluate" in refused(capsys, pkg, "ground_truth.lateral")
    assert not (tmp_path / "out").exists()


def test_restore_steps_below_the_default_start_is_one_line(make_package, tmp_path, capsys):
    """``--steps 1`` alone: the default start step (4) does not fit; one line naming both options."""
    from symdrive_core.cli import main

    pkg = make_package(n_frames=2, lateral=(1.0,))
    assert main(["restore", str(pkg), "--steps", "1", "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--n-start 4 (the default)" in err and "--steps 1" in err
    assert not (tmp_path / "r").exists()
