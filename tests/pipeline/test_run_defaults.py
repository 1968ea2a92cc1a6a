"""``symdrive run PACKAGE`` with no options on a package with lateral offsets and recorded images:
every stage end to end (refinement on), a window of frames and offsets, and a re-run after a
failed stage that reuses what was finished (the restorer's adaptation, the run's slowest stage, only
where every stage runs: its reuse is tests/pipeline/test_adapt.py's)."""

import json

import pytest

from symdrive_core.cli import main
from symdrive_core.io.ply import read_splats, write_splats
from symdrive_core.pipeline import stages
from tests.conftest import manifest_dict, random_gaussians, write_recorded_images


@pytest.fixture
def recorded_package(tmp_path):
    """Three frames with recorded images (the background's own renders), offsets +-1 m, an inserted
    car harmonized and fine-tuned: every stage of the default plan has work."""
    root = tmp_path / "pkg"
    root.mkdir()
    d = manifest_dict(n_frames=3, lateral=(-1.0, 1.0), harmonize=True)
    d["effects"]["finetune"] = True
    background = random_gaussians(200, 0, 1, (10, 0, 1), 3.0)
    write_splats(root / "background.ply", background)
    write_splats(root / "car_0.ply", random_gaussians(50, 1, 10, spread=0.8))
    write_recorded_images(root, d, background)
    (root / "manifest.json").write_text(json.dumps(d))
    return root


def _stages(out):
    return {s["name"]: s for s in json.loads((out / "report.json").read_text())["stages"]}


def test_default_run_runs_every_stage(recorded_package, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", str(recorded_package), "--out", str(out), "--quiet"]) == 0
    ran = {name for name, s in _stages(out).items() if s["ran"]}
    assert {"render", "restore", "refine", "harmonize", "finetune"} <= ran
    refine = _stages(out)["refine"]
    assert refine["seconds"] > 0 and refine["iterations"] == stages.StageOptions().refine.iters
    assert len(read_splats(out / "refine" / "background.ply")) > 0
    assert sorted(p.name for p in (out / "restore" / "front").iterdir()) == ["+1", "-1"]
    assert "ran  refine" in capsys.readouterr().out


def test_window_of_frames_and_offsets_on_both_sides(recorded_package, tmp_path):
    out = tmp_path / "out"
    assert main(["run", str(recorded_package), "--out", str(out), "--quiet", "--no-refine", "--no-adapt",
                 "--frames", "1", "--offsets", "0.5"]) == 0
    assert sorted(p.relative_to(out).as_posix() for p in (out / "restore").rglob("*.png")) == [
        "restore/front/+0.5/000001.png", "restore/front/-0.5/000001.png"]
    assert sorted(p.name for p in (out / "render" / "front").glob("*.png")) == ["000001.png"]
    report = _stages(out)
    assert report["render"]["frames_rendered"] == 1
    assert "-0.5, 0.5 m requested on the command line" in report["restore"]["reason"]


def test_a_frame_outside_the_package_is_one_line_and_exit_2(recorded_package, tmp_path, capsys):
    assert main(["run", str(recorded_package), "--out", str(tmp_path / "out"), "--frames", "0,7"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "manifest.json" in err and "frame 7" in err
    assert not (tmp_path / "out" / "report.json").exists()


def test_rerun_after_a_failed_stage_reuses_finished_work(recorded_package, tmp_path, monkeypatch):
    out = tmp_path / "out"

    def broken(ctx):
        raise RuntimeError("harmonizer failed")

    monkeypatch.setitem(stages.STAGE_RUNNERS, "harmonize", broken)
    with pytest.raises(RuntimeError):
        main(["run", str(recorded_package), "--out", str(out), "--quiet", "--no-adapt"])
    monkeypatch.undo()
    restored = {p: p.stat().st_mtime_ns for p in (out / "restore").rglob("*.png")}
    assert len(restored) == 6 and (out / "refine" / "background.ply").exists()

    def refit(*args, **kwargs):
        raise AssertionError("the refined reconstruction on disk should have been reused")

    monkeypatch.setattr("symdrive_core.diffusion.refine.refine_gaussians", refit)
    assert main(["run", str(recorded_package), "--out", str(out), "--quiet", "--no-adapt"]) == 0
    assert {p: p.stat().st_mtime_ns for p in (out / "restore").rglob("*.png")} == restored
    report = _stages(out)
    assert report["refine"]["ran"] and report["refine"]["reused"] and report["harmonize"]["ran"]


def test_plan_takes_the_same_window_as_run(recorded_package, capsys):
    assert main(["plan", str(recorded_package), "--frames", "1", "--offsets", "0.5", "--json"]) == 0
    stages = {s["name"]: s for s in json.loads(capsys.readouterr().out)["stages"]}
    assert stages["render"]["frames"] == [1] and stages["restore"]["frames"] == [1]
    assert stages["restore"]["offsets"] == [-0.5, 0.5]


def test_scoring_keeps_to_the_frame_window(tmp_path):
    root = tmp_path / "pkg"
    root.mkdir()
    d = manifest_dict(n_frames=4, actors=())
    background = random_gaussians(200, 0, 1, (10, 0, 1), 3.0)
    write_splats(root / "background.ply", background)
    write_recorded_images(root, d, background)
    d["ground_truth"] = {"camera": "front", "train_frames": [0, 2], "heldout_frames": [1, 3]}
    (root / "manifest.json").write_text(json.dumps(d))
    scored = {}
    for window in ("0:3", "3", "0"):
        out = tmp_path / f"out{window.replace(':', '_')}"
        assert main(["run", str(root), "--out", str(out), "--quiet", "--frames", window]) == 0
        scored[window] = json.loads((out / "report.json").read_text())["metrics"].get("reconstruction", {})
    assert scored["0:3"]["frames"] == 2 and scored["3"]["frames"] == 1
    assert scored["0"] == {}  # no held-out frame in the window: nothing scored
