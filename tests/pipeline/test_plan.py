import json
import subprocess
import sys

import numpy as np

from symdrive_core.cli import main
from symdrive_core.io.ply import write_splats
from symdrive_core.pipeline.plan import format_plan, make_plan, sh_degree_of
from symdrive_core.scene import box_corners_world, box_in_frustum, load_manifest
from tests.conftest import look_at_c2w, random_gaussians


def _stages(plan):
    return {s.name: s.run for s in plan.stages}


def test_full_scene_runs_every_effect(make_package):
    m = load_manifest(make_package(lateral=(1.0, 2.0), sun=[1, 0, -1], harmonize=True))
    m.effects.finetune = True
    plan = make_plan(m)
    # no recorded images: nothing to refine against or adapt the restorer on
    assert _stages(plan) == {"reconstruct": False, "render": True, "adapt": False, "restore": True, "refine": False,
                             "harmonize": True, "cast_shadow": True, "inpaint": False, "finetune": True,
                             "sh_eval": True, "evaluate": False}
    assert plan.stage("refine").reason == "no recorded images to refine against"
    assert plan.needs_diffusion


def test_no_inserted_actor_no_diffusion(make_package):
    plan = make_plan(load_manifest(make_package(actors=(), harmonize=True)))
    assert not plan.runs("harmonize") and plan.stage("harmonize").reason == "no inserted actor"
    assert not plan.runs("finetune") and not plan.runs("restore")
    assert not plan.needs_diffusion


def test_no_sun_no_cast_shadow(make_package):
    plan = make_plan(load_manifest(make_package(harmonize=True, sun=None)))
    assert plan.runs("harmonize")
    assert not plan.runs("cast_shadow") and plan.stage("cast_shadow").reason == "no sun in the scene"


def test_cast_shadow_needs_a_sun_above_the_horizon_and_an_inserted_vehicle(make_package):
    sunny = make_plan(load_manifest(make_package(harmonize=False, sun=[1, 0, -1])))
    assert sunny.runs("cast_shadow") and not sunny.runs("harmonize")  # shadows do not need the diffusion model
    assert sunny.stage("cast_shadow").frames and "0.40" in sunny.stage("cast_shadow").reason
    low = make_plan(load_manifest(make_package("low", sun=[1, 0, 0.1])))
    assert not low.runs("cast_shadow") and low.stage("cast_shadow").reason == "sun at or below the horizon"
    empty = make_plan(load_manifest(make_package("empty", actors=(), sun=[1, 0, -1])))
    assert not empty.runs("cast_shadow")
    off = load_manifest(make_package("off", sun=[1, 0, -1]))
    off.effects.shadows = False
    assert make_plan(off).stage("cast_shadow").reason == "shadows off in the scene's effects"


def test_three_scenes_three_stage_lists(make_package):
    demo = make_plan(load_manifest(make_package("demo", lateral=(1.0,), harmonize=True, sun=[0, 1, -1])))
    empty = make_plan(load_manifest(make_package("empty", actors=(), lateral=(1.0,), sun=[0, 1, -1])))
    dark = make_plan(load_manifest(make_package("dark", lateral=(1.0,), harmonize=True, sun=None)))
    lists = [tuple(s.name for s in p.stages if s.run) for p in (demo, empty, dark)]
    assert len(set(lists)) == 3


def test_actor_outside_every_frustum_is_culled(make_package):
    path = make_package(actors=("ahead", "behind"), harmonize=True)
    d = json.loads(path.read_text())
    d["actors"][1]["poses"] = [{"translation": [-40.0, 0, 0.75], "rotation": [1, 0, 0, 0]}] * 3
    path.write_text(json.dumps(d))
    plan = make_plan(load_manifest(path))
    assert all(ids == ["ahead"] for ids in plan.visible["front"].values())
    assert all(ids == ["behind"] for ids in plan.culled["front"].values())
    assert plan.stage("harmonize").actors == ["ahead"]
    assert "culled behind in front frames 0-2" in format_plan(plan)


def test_sh_degree_zero_skips_sh_eval(make_package, tmp_path):
    path = make_package()
    write_splats(path.parent / "background.ply", random_gaussians(20, 0))
    write_splats(path.parent / "car_0.ply", random_gaussians(20, 0))
    plan = make_plan(load_manifest(path))
    assert plan.sh_degrees == {"background": 0, "car_0": 0}
    assert not plan.runs("sh_eval")
    write_splats(path.parent / "car_0.ply", random_gaussians(20, 2))
    assert sh_degree_of(path.parent / "car_0.ply") == 2
    assert make_plan(load_manifest(path)).runs("sh_eval")


def test_unchanged_inputs_are_cached(make_package):
    path = make_package(harmonize=True)
    first = make_plan(load_manifest(path))
    running = [s.name for s in first.stages if s.run]
    state = {"inputs_hash": first.inputs_hash, "completed": running}
    again = make_plan(load_manifest(path), previous=state)
    assert all(s.cached for s in again.stages if s.run)
    # A stage is reused only when everything after it is reused too.
    partial = make_plan(load_manifest(path), previous={"inputs_hash": first.inputs_hash,
                                                       "completed": ["render"]})
    assert not any(s.cached for s in partial.stages)
    write_splats(path.parent / "car_0.ply", random_gaussians(21, 1))
    changed = make_plan(load_manifest(path), previous=state)
    assert changed.inputs_hash != first.inputs_hash and not any(s.cached for s in changed.stages)


def test_frustum_test_explicit():
    K = np.array([[50.0, 0, 32], [0, 50.0, 24], [0, 0, 1]])
    w2c = np.linalg.inv(look_at_c2w((0, 0, 1), (10, 0, 1)))
    box = lambda t: box_corners_world([-1, -1, -1], [1, 1, 1], np.eye(3), t)
    assert box_in_frustum(box([10, 0, 1]), w2c, K, 64, 48)
    assert not box_in_frustum(box([-10, 0, 1]), w2c, K, 64, 48)      # behind
    assert not box_in_frustum(box([10, 30, 1]), w2c, K, 64, 48)      # far left
    assert box_in_frustum(box([0.5, 0, 1]), w2c, K, 64, 48)          # camera inside the box


def test_plan_command_never_imports_torch_or_diffusion(make_package):
    """Only the torch-free diffusion modules: the configs, the defaults, and the adaptation's config and
    drive identity."""
    path = make_package(actors=())
    code = ("import sys\nfrom symdrive_core.cli import main\n"
            f"rc = main(['plan', {str(path)!r}])\n"
            "bad = [m for m in sys.modules if m.split('.')[0] in ('torch', 'diffusers')"
            " or m.startswith('symdrive_core.diffusion.') and m.split('.')[2] not in ('config', 'defaults', 'adapt')]\n"
            "print('LOADED', bad)\nsys.exit(rc)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "LOADED []" in out.stdout
    assert "skip   harmonize      no inserted actor" in out.stdout


def test_plan_command_json(make_package, capsys):
    assert main(["plan", str(make_package(lateral=(0.5,))), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["needs_diffusion"] is True
    assert [s["name"] for s in data["stages"]][:6] == ["reconstruct", "render", "cast_shadow", "inpaint", "adapt",
                                                       "restore"]


def test_sh_degree_of_a_compressed_ply_comes_from_its_sh_element(tmp_path):
    from tests.compressed_ply_files import BOX, write_compressed_ply

    path = tmp_path / "car.compressed.ply"
    write_compressed_ply(path, [BOX], [(0, 0, 0, 0)])
    assert sh_degree_of(path) == 0
    write_compressed_ply(path, [BOX], [(0, 0, 0, 0)], sh=np.zeros((1, 24), np.uint8))
    assert sh_degree_of(path) == 2


def _recorded_vehicle_without_gaussians(manifest_path, moved_m: float = 0.0):
    """``manifest_path``'s first actor made a recorded vehicle with no Gaussians of its own
    (``moved_m``: its last pose moved that far from where the drive saw it)."""
    d = json.loads(manifest_path.read_text())
    a = d["actors"][0]
    a.update(kind="existing", assets={}, recorded_poses=[dict(p) for p in a["poses"]])
    a["poses"][-1] = {**a["poses"][-1], "translation": [a["poses"][-1]["translation"][0] + moved_m, 2.0, 0.75]}
    a["recorded_poses"][-1]["translation"] = [a["recorded_poses"][-1]["translation"][0], 2.0, 0.75]
    manifest_path.write_text(json.dumps(d))
    return load_manifest(manifest_path)


def test_a_fit_with_every_frame_held_out_stops_naming_the_split(tmp_path, capsys):
    from symdrive_core.io.points import write_points
    from tests.conftest import manifest_dict, write_recorded_images

    root = tmp_path / "pkg"
    root.mkdir()
    d = manifest_dict(actors=(), background=None)
    write_recorded_images(root, d, random_gaussians(200, 0, 1, (10, 0, 1), 3.0))
    pts = np.random.default_rng(0).normal(size=(50, 3)) + [10, 0, 1]
    write_points(root / "points.ply", pts, np.full_like(pts, 0.5))
    d["background"] = {"splats": None, "points": "points.ply"}
    d["ground_truth"] = {"camera": "front", "train_frames": [], "heldout_frames": [0, 1, 2]}
    (root / "manifest.json").write_text(json.dumps(d))
    for command in (["plan", str(root)], ["reconstruct", str(root), "--out", str(tmp_path / "fit")]):
        assert main(command) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "ground_truth.train_frames: all 3 frames are held out" in err, err
    assert not (tmp_path / "fit").exists()


def test_a_run_refused_at_its_plan_leaves_no_output_folder_behind(make_package, tmp_path, capsys):
    path = make_package()
    _recorded_vehicle_without_gaussians(path, moved_m=3.0)
    out = tmp_path / "runs" / "deep" / "er"
    assert main(["run", str(path.parent), "--out", str(out), "--quiet"]) == 2
    assert "actor 'car_0' is a recorded vehicle with no Gaussians yet" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()
