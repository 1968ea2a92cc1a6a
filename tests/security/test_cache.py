"""The cache key covers everything that changes the result, and only that."""

import json
from dataclasses import replace

from symdrive_core.io.ply import write_splats
from symdrive_core.pipeline.plan import PlanOptions
from symdrive_core.pipeline.run import run_scene
from symdrive_core.pipeline.stages import StageOptions
from tests.conftest import random_gaussians
from tests.security.hostile import write_package


def _samples(k: int) -> StageOptions:
    return StageOptions(sampler=replace(StageOptions().sampler, samples=k))


def _stage(report, name):
    return next(s for s in report["stages"] if s["name"] == name)


def test_other_stage_options_are_not_served_from_the_cache(tmp_path):
    pkg = write_package(tmp_path / "pkg")
    out = tmp_path / "out"
    run_scene(pkg, out, progress=False, options=PlanOptions(frames=[0]), stage_options=_samples(1))
    again = run_scene(pkg, out, progress=False, options=PlanOptions(frames=[0]), stage_options=_samples(1))
    assert not _stage(again, "render")["ran"] and "cached" in _stage(again, "render")["reason"]
    other = run_scene(pkg, out, progress=False, options=PlanOptions(frames=[0]), stage_options=_samples(2))
    assert _stage(other, "render")["ran"] and _stage(other, "render")["frames_rendered"] == 1
    window = run_scene(pkg, out, progress=False, options=PlanOptions(frames=[0, 1]))
    assert _stage(window, "render")["ran"] and _stage(window, "render")["frames_rendered"] == 2


def test_a_package_under_a_folder_named_output_sees_its_assets_change(tmp_path):
    pkg = write_package(tmp_path / "output" / "pkg")
    out = tmp_path / "out"
    run_scene(pkg, out, progress=False)
    write_splats(pkg.parent / "car_0.ply", random_gaussians(60, 1, 99, spread=0.8))
    changed = run_scene(pkg, out, progress=False)
    assert _stage(changed, "render")["ran"] and _stage(changed, "render")["frames_rendered"] == 2


def test_an_out_inside_the_package_not_named_output_resumes(tmp_path):
    pkg = write_package(tmp_path / "pkg")
    out = pkg.parent / "renders"
    run_scene(pkg, out, progress=False)
    again = run_scene(pkg, out, progress=False)
    assert not _stage(again, "render")["ran"]


def test_a_same_sized_same_second_edit_of_a_small_file_is_seen(tmp_path):
    """Small files are keyed by their bytes: an edit that keeps size and mtime still counts."""
    import os

    pkg = write_package(tmp_path / "pkg")
    out = tmp_path / "out"
    run_scene(pkg, out, progress=False)
    ply = pkg.parent / "car_0.ply"
    st = os.stat(ply)
    data = bytearray(ply.read_bytes())
    data[-5] ^= 0x01
    ply.write_bytes(bytes(data))
    os.utime(ply, ns=(st.st_atime_ns, st.st_mtime_ns))
    changed = run_scene(pkg, out, progress=False)
    assert _stage(changed, "render")["ran"]


def test_two_packages_into_one_output_never_share_frames(tmp_path):
    a = write_package(tmp_path / "a")
    b = write_package(tmp_path / "b", lambda d: d.update(name="other"))
    out = tmp_path / "out"
    run_scene(a, out, progress=False)
    second = run_scene(b, out, progress=False)
    assert _stage(second, "render")["frames_rendered"] == 2 and _stage(second, "render")["frames_reused"] == 0
    assert json.loads((out / "report.json").read_text())["scene"] == "other"
