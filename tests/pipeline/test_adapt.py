"""The adapt stage in the pipeline: planned only where the restorer's weights were trained on
another drive, its weights cached under the output folder and reused by later runs, and the
restore stage sampling with them."""

import json
from dataclasses import replace

import pytest
from safetensors import safe_open
from safetensors.numpy import save_file

from symdrive_core.diffusion import defaults, models
from symdrive_core.diffusion.adapt import AdaptConfig, drive_identity
from symdrive_core.diffusion.train import WEIGHTS
from symdrive_core.io.ply import write_splats
from symdrive_core.pipeline.plan import PlanOptions, make_plan
from symdrive_core.pipeline.run import run_scene
from symdrive_core.pipeline.stages import StageOptions
from symdrive_core.scene import load_manifest
from symdrive_core.world.demo import DEMO_PACKAGE
from tests.optim.conftest import synthetic_package  # noqa: F401  (fixture)


@pytest.fixture
def drive(synthetic_package):  # noqa: F811
    """The synthetic package with a reconstruction and one lateral offset to restore."""
    root, g = synthetic_package
    write_splats(root / "bg.ply", g)
    m = load_manifest(root)
    m.background_splats = "bg.ply"
    m.effects.lateral_offsets = [0.5]
    m.save(root / "manifest.json")
    return root


def stamped_weights(path, drive: dict | None = None, family: list[dict] | None = None):
    """A copy of the shipped guided weights whose metadata says they were trained on ``drive``, or
    on a family of pairs files, one per drive of ``family``."""
    with safe_open(str(defaults.GUIDED_WEIGHTS), "np") as f:
        meta, tensors = dict(f.metadata()), {k: f.get_tensor(k) for k in f.keys()}  # noqa: SIM118
    inner = json.loads(meta["meta"])
    inner["data"] = ({"drive": drive} if family is None else
                     {"files": [{"file": f"street_{i}.safetensors", "drive": d} for i, d in enumerate(family)]})
    save_file(tensors, str(path), metadata={**meta, "meta": json.dumps(inner)})
    return path


def test_the_plan_adapts_only_a_restorer_trained_on_another_drive(drive, make_package, tmp_path, monkeypatch):
    m = load_manifest(drive)
    adapt = make_plan(m).stage("adapt")
    assert adapt.run and "street-0" in adapt.reason and adapt.frames == m.ground_truth["train_frames"]
    assert not make_plan(m, PlanOptions(adapt=False)).stage("adapt").run
    assert make_plan(m).stages.index(adapt) < [s.name for s in make_plan(m).stages].index("restore")

    monkeypatch.setattr(defaults, "GUIDED_WEIGHTS", stamped_weights(tmp_path / "geo.safetensors",
                                                                    drive_identity(m, drive / "bg.ply")))
    skip = make_plan(m).stage("adapt")
    assert not skip.run and "trained on this drive" in skip.reason
    monkeypatch.undo()

    others = [{"scene": f"street-{i}", "identity": f"{i:016x}"} for i in range(3)]
    monkeypatch.setattr(defaults, "GUIDED_WEIGHTS", stamped_weights(tmp_path / "family.safetensors", family=others))
    unseen = make_plan(m).stage("adapt")
    assert unseen.run and "3 drives ('street-0', 'street-1', 'street-2')" in unseen.reason
    family = [*others, drive_identity(m, drive / "bg.ply")]
    monkeypatch.setattr(defaults, "GUIDED_WEIGHTS", stamped_weights(tmp_path / "family.safetensors", family=family))
    member = make_plan(m).stage("adapt")  # one of the family's drives
    assert not member.run and "trained on this drive" in member.reason
    monkeypatch.undo()

    demo = make_plan(load_manifest(DEMO_PACKAGE)).stage("adapt")  # the street the shipped weights learnt
    assert not demo.run and "trained on this drive" in demo.reason
    no_images = make_plan(load_manifest(make_package(lateral=(1.0,)))).stage("adapt")
    assert not no_images.run and "recorded image" in no_images.reason
    m.effects.lateral_offsets = []
    assert not make_plan(m).stage("adapt").run


def test_runs_adapt_once_and_restore_samples_with_the_adapted_weights(drive, tmp_path, monkeypatch):
    loaded = []
    load_builtin = models.load_builtin
    monkeypatch.setattr(models, "load_builtin", lambda path=defaults.DEFAULT_WEIGHTS: loaded.append(path)
                        or load_builtin(path))
    window = PlanOptions(refine=False, frames=[0], offsets=(0.5,))
    fast = dict(sampler=replace(StageOptions().sampler, steps=2, n_start=1, samples=1),
                eval_methods=("single_view",),
                adapt=AdaptConfig(iters=2, offsets=(0.5,), cycle_offsets=(1.0,), cycle_iters=10))
    out = tmp_path / "out"
    report = run_scene(drive, out, options=window, stage_options=StageOptions(**fast),
                       progress=False)
    row = next(s for s in report["stages"] if s["name"] == "adapt")
    assert row["ran"] and not row["reused"] and row["guided"] and row["steps"] == 2
    assert row["strength"] == {"strength": 1.0, "keep_warp": True, "frames": [], "fit": None}  # too few frames to hold out
    weights = out / row["weights"] / WEIGHTS
    assert weights.exists() and weights in loaded  # the restore stage loaded the adapted weights
    assert next(s for s in report["stages"] if s["name"] == "restore")["method"] == "geo_ar_d1.0"

    # another run key (the sampler's seed) clears the run's outputs, not the adapted restorer
    made = weights.stat().st_mtime_ns
    reseeded = StageOptions(**{**fast, "sampler": replace(fast["sampler"], seed=1)})
    again = run_scene(drive, out, options=window, stage_options=reseeded, progress=False)
    row = next(s for s in again["stages"] if s["name"] == "adapt")
    assert row["ran"] and row["reused"] and weights.stat().st_mtime_ns == made
    assert (out / "restore" / "front" / "+0.5" / "000000.png").exists()


def test_the_command_line_turns_adaptation_off_and_checks_its_budget(drive, capsys):
    from symdrive_core.cli import main

    assert main(["plan", str(drive), "--json"]) == 0
    assert next(s for s in json.loads(capsys.readouterr().out)["stages"] if s["name"] == "adapt")["run"]
    assert main(["plan", str(drive), "--no-adapt", "--json"]) == 0
    row = next(s for s in json.loads(capsys.readouterr().out)["stages"] if s["name"] == "adapt")
    assert not row["run"] and row["reason"] == "adaptation disabled"
    for bad in (["--adapt-seconds", "-1"], ["--adapt-seconds", "nan"], ["--adapt-iters", "0"]):
        with pytest.raises(SystemExit) as exc:
            main(["run", str(drive), *bad])
        last = capsys.readouterr().err.strip().splitlines()[-1]
        assert exc.value.code == 2 and last.startswith("symdrive run: error:") and bad[0] in last


def test_the_command_line_leaves_a_rigs_pairs_out_of_the_adaptation(drive, monkeypatch):
    import symdrive_core.pipeline.run as run_module
    from symdrive_core.cli import main

    seen = []
    monkeypatch.setattr(run_module, "run_scene",
                        lambda *a, stage_options, **k: seen.append(stage_options.adapt) or {"stages": []})
    assert main(["run", str(drive), "--quiet"]) == 0
    assert main(["run", str(drive), "--quiet", "--no-sensor-pairs", "--adapt-iters", "7"]) == 0
    assert seen[0] == AdaptConfig() and seen[0].sensor_pairs
    assert seen[1] == replace(AdaptConfig(), sensor_pairs=False, iters=7)
