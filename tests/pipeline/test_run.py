"""``symdrive run`` end to end on tiny packages: outputs, report.json, caching, kill-and-resume,
and the same outputs from the in-process and the Ray executor."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.io.images import read_image, read_mask
from symdrive_core.io.ply import write_splats
from symdrive_core.pipeline.batch import run_batch
from symdrive_core.pipeline.run import run_scene
from tests.conftest import random_gaussians

REPORT_KEYS = {"version", "scene", "device", "stages", "metrics"}


def _outputs(out):
    return sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file() and p.suffix in (".png", ".exr"))


def test_run_writes_frames_masks_depth_and_report(make_package, tmp_path):
    path = make_package(n_frames=3)
    out = tmp_path / "out"
    report = run_scene(path, out, progress=False)
    assert _outputs(out) == sorted(
        [f"render/front/{i:06d}.png" for i in range(3)] + [f"render/front/{i:06d}.depth.exr" for i in range(3)]
        + [f"masks/front/car_0/{i:06d}.png" for i in range(3)])
    on_disk = json.loads((out / "report.json").read_text())
    assert on_disk == report and REPORT_KEYS <= set(report)
    stages = {s["name"]: s for s in report["stages"]}
    assert stages["render"]["ran"] and stages["render"]["frames_rendered"] == 3 and stages["render"]["seconds"] > 0
    assert not stages["harmonize"]["ran"] and not stages["restore"]["ran"]
    assert report["metrics"] == {}  # no ground truth in this package: nothing is made up
    rgb = read_image(out / "render/front/000000.png", channels=3)
    mask = read_mask(out / "masks/front/car_0/000000.png")
    assert rgb.shape == (24, 32, 3) and mask.shape == (24, 32)
    assert 0.0 < mask.max() <= 1.0  # the car ahead of the camera covers some pixels


def test_rerun_with_same_inputs_reuses_everything(make_package, tmp_path):
    path = make_package(n_frames=2)
    out = tmp_path / "out"
    run_scene(path, out, progress=False)
    mtimes = {p: os.stat(out / p).st_mtime_ns for p in _outputs(out)}
    again = run_scene(path, out, progress=False)
    assert {p: os.stat(out / p).st_mtime_ns for p in _outputs(out)} == mtimes
    render = next(s for s in again["stages"] if s["name"] == "render")
    assert not render["ran"] and "unchanged" in render["reason"]
    # A changed input invalidates the outputs.
    write_splats(path.parent / "car_0.ply", random_gaussians(60, 1, 99, spread=0.8))
    changed = run_scene(path, out, progress=False)
    assert next(s for s in changed["stages"] if s["name"] == "render")["frames_rendered"] == 2


def test_bad_package_exits_2_naming_the_field(make_package, tmp_path, capsys):
    path = make_package()
    d = json.loads(path.read_text())
    d["cameras"][0]["width"] = -5
    path.write_text(json.dumps(d))
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "manifest.json" in err and "width" in err
    assert not (tmp_path / "out" / "report.json").exists()


def test_killed_run_resumes_without_redoing_finished_frames(make_package, tmp_path):
    frames = 120
    path = make_package(n_frames=frames, width=160, height=120)
    write_splats(path.parent / "background.ply", random_gaussians(20000, 0, 1, (10, 0, 1), 3.0))
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "symdrive_core.cli", "run", str(path), "--out", str(out), "--quiet"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    renders = out / "render" / "front"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if len(list(renders.glob("[0-9]*.png"))) >= 2:
            break
        time.sleep(0.005)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done_before = sorted(renders.glob("[0-9]*.png"))
    assert 2 <= len(done_before) < frames, "the run was not killed part-way; make the scene slower"
    for p in done_before:  # what exists under its final name is complete
        assert read_image(p).shape == (120, 160, 3)
    mtimes = {p.name: p.stat().st_mtime_ns for p in done_before}

    rerun = subprocess.run(cmd, capture_output=True, text=True)
    assert rerun.returncode == 0, rerun.stderr
    report = json.loads((out / "report.json").read_text())
    render = next(s for s in report["stages"] if s["name"] == "render")
    assert render["frames_rendered"] + render["frames_reused"] == frames
    assert render["frames_reused"] >= len(done_before)
    assert {p.name: p.stat().st_mtime_ns for p in done_before} == mtimes  # finished frames untouched
    assert len(list(renders.glob("[0-9]*.png"))) == frames
    assert not list(out.rglob(".*.part*")), "a temporary file of the killed run was left behind"


def test_a_batch_checks_every_package_before_it_runs_any(make_package, tmp_path, capsys):
    good = make_package("good", n_frames=2).parent
    bad = make_package("bad", n_frames=2)
    d = json.loads(bad.read_text())
    d["actors"][0]["assets"]["splats"] = "missing.ply"
    bad.write_text(json.dumps(d))
    assert main(["batch", str(good), str(bad.parent), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "actors[0].assets.splats: file not found: missing.ply" in err, err
    assert not (tmp_path / "out").exists()


def test_two_packages_of_one_folder_name_are_refused_naming_both(make_package, tmp_path, capsys):
    (tmp_path / "day1").mkdir()
    (tmp_path / "day2").mkdir()
    a = make_package("day1/street").parent
    b = make_package("day2/street").parent
    assert main(["batch", str(a), str(b), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{b}: PACKAGES: its output" in err and f"that of {a} too" in err, err
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_ray_executor_gives_the_same_outputs_as_local(make_package, tmp_path):
    ray = pytest.importorskip("ray")
    packages = [str(make_package(name, n_frames=5).parent) for name in ("scene_a", "scene_b")]
    local = run_batch(packages, tmp_path / "local", progress=False)
    try:
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
        distributed = run_batch(packages, tmp_path / "ray", executor="ray", frames_per_task=2)
    finally:
        ray.shutdown()
    strip = lambda r: [{k: v for k, v in s.items() if k not in ("seconds", "frames_rendered", "frames_reused")}
                       for s in r["stages"]]
    assert [strip(r) for r in local] == [strip(r) for r in distributed]
    for name in ("scene_a", "scene_b"):
        a, b = tmp_path / "local" / name, tmp_path / "ray" / name
        assert _outputs(a) == _outputs(b) and len(_outputs(a)) == 15
        for rel in _outputs(a):
            np.testing.assert_array_equal(read_image(a / rel), read_image(b / rel))


def test_sunny_scene_casts_inserted_vehicles_shadows_into_the_render(make_package, tmp_path):
    from tests.insertion import synthetic

    def street(name, sun):
        path = make_package(name, n_frames=2, sun=sun)
        write_splats(path.parent / "background.ply", synthetic.ground())
        write_splats(path.parent / "car_0.ply", synthetic.car(800))
        return path

    dark = run_scene(street("dark", None), tmp_path / "out_dark", progress=False)
    assert not next(s for s in dark["stages"] if s["name"] == "cast_shadow")["ran"]
    assert not (tmp_path / "out_dark" / "shadows").exists()
    run_scene(street("sunny", [0.3, 0.4, -1.0]), tmp_path / "out_sunny", progress=False)
    for i in range(2):
        shade = read_mask(tmp_path / f"out_sunny/shadows/front/{i:06d}.png")
        car = read_mask(tmp_path / f"out_sunny/masks/front/car_0/{i:06d}.png")
        lit = read_image(tmp_path / f"out_dark/render/front/{i:06d}.png", channels=3)
        shaded = read_image(tmp_path / f"out_sunny/render/front/{i:06d}.png", channels=3)
        assert np.array_equal(shaded[shade == 0], lit[shade == 0])  # outside the shadow: the very same pixels
        ground = (shade > 0.5) & (car < 0.01) & (lit.sum(-1) > 0.05)
        assert ground.sum() > 5
        assert (shaded[ground].sum(-1) < lit[ground].sum(-1) - 0.02).all()
