"""Reconstruction schedules against time: the curves, the time to the default's PSNR, the rows of
``bench accuracy-time``."""

import copy
import json
from dataclasses import replace

import pytest

from symdrive_core.bench import reconstruction as bench
from symdrive_core.bench.accuracy_time import run_settings
from symdrive_core.eval.views import evaluate_heldout
from symdrive_core.io.images import read_image
from symdrive_core.optim.config import PoseRefineConfig, ReconstructConfig
from symdrive_core.optim.pose_refine import with_refined
from symdrive_core.optim.reconstruct import Fit
from symdrive_core.scene import load_manifest
from tests.optim.conftest import write_package
from tests.optim.moving_box import write_moving_box
from tests.optim.test_multi_camera import BASELINE_M, add_camera

TINY = dict(densify_from=10, densify_every=10, sky_points=0)


@pytest.fixture(scope="module")
def package(tmp_path_factory):
    root, _ = write_package(tmp_path_factory.mktemp("bench") / "pkg")
    return load_manifest(root)


def test_time_to_the_defaults_psnr_is_a_ratio_of_its_whole_time():
    rows = [{"schedule": "a", "iteration": 0, "seconds": 0.0, "psnr": 20.0, "ssim": 0.5, "gaussians": 10},
            {"schedule": "b", "iteration": 0, "seconds": 0.0, "psnr": 20.0, "ssim": 0.5, "gaussians": 10},
            {"schedule": "a", "iteration": 10, "seconds": 10.0, "psnr": 25.0, "ssim": 0.7, "gaussians": 10},
            {"schedule": "b", "iteration": 10, "seconds": 4.0, "psnr": 25.5, "ssim": 0.7, "gaussians": 10},
            {"schedule": "a", "iteration": 20, "seconds": 20.0, "psnr": 26.0, "ssim": 0.8, "gaussians": 10},
            {"schedule": "b", "iteration": 20, "seconds": 8.0, "psnr": 25.9, "ssim": 0.8, "gaussians": 10}]
    s = bench.summary(rows, "a")
    assert s["target_psnr"] == 26.0 and s["schedules"]["a"]["time_ratio"] == 1.0
    assert s["schedules"]["b"]["seconds_to_target"] is None and s["schedules"]["b"]["time_ratio"] is None
    assert bench.seconds_to_reach(rows, "b", 25.2) == 4.0
    assert "| b | 20 | 25.90 | 0.8000 | 8 | never |  |" in bench.format_summary(s)


def test_the_default_schedule_is_the_one_the_config_resolves_to_for_the_images():
    configs = bench.schedule_configs(40)
    assert all(c.iters == 40 for c in configs.values())
    big = ReconstructConfig().coarse_to_fine_pixels
    assert bench.default_name(configs, big - 1) == "full resolution"
    assert bench.default_name(configs, big) == "coarse to fine"


def test_curves_score_each_schedule_every_k_iterations_and_write_the_figure(package, tmp_path):
    configs = {name: ReconstructConfig(iters=40, **TINY, **over) for name, over in bench.SCHEDULES.items()}
    rows = bench.curves(package, configs, every=20, progress=False)
    for name in configs:
        mine = [r for r in rows if r["schedule"] == name]
        assert [r["iteration"] for r in mine] == [0, 20, 40]
        assert mine[0]["seconds"] == 0.0 < mine[1]["seconds"] < mine[2]["seconds"]
        assert mine[-1]["psnr"] > mine[0]["psnr"]
    last = {r["schedule"]: r["gaussians"] for r in rows if r["iteration"] == 40}
    for plain in ("coarse to fine", "full resolution"):  # pruned when densification ended
        assert last[f"{plain}, pruned 0.6"] < 0.5 * last[plain]
    s = bench.summary(rows, bench.default_name(configs, bench.training_pixels(package)))
    paths = bench.write_outputs(rows, s, configs, tmp_path, "synthetic")
    assert json.loads(paths["json"].read_text())["configs"]["coarse to fine"]["resolution_schedule"] == [0.1, 0.3]
    assert paths["csv"].read_text().startswith("schedule,iteration,seconds,psnr,ssim,gaussians")
    assert read_image(paths["png"]).ndim == 3


def test_schedules_that_differ_in_the_prune_share_one_fit_until_it(package, monkeypatch):
    """The copies continue exactly as fits of their own would."""
    from symdrive_core.optim import reconstruct

    plain = ReconstructConfig(iters=40, **TINY)
    pruned = replace(plain, importance_prune=0.5)
    alone = bench.curves(package, {"pruned": pruned}, every=15, progress=False)
    starts = []
    start = reconstruct.Fit.start
    monkeypatch.setattr(reconstruct.Fit, "start", staticmethod(lambda m, cfg: starts.append(cfg) or start(m, cfg)))
    rows = bench.curves(package, {"plain": plain, "pruned": pruned}, every=15, progress=False)
    assert len(starts) == 1 and plain.densify_end == 24  # one fit to iteration 15, copied there
    shared = [{k: r[k] for k in ("iteration", "psnr", "ssim", "gaussians")} for r in rows if r["schedule"] == "pruned"]
    assert shared == [{k: r[k] for k in ("iteration", "psnr", "ssim", "gaussians")} for r in alone]
    assert [r["iteration"] for r in shared] == [0, 15, 30, 40]
    ends = {r["schedule"]: r["gaussians"] for r in rows if r["iteration"] == 40}
    assert ends["pruned"] < 0.6 * ends["plain"]


def test_accuracy_time_rows_fit_a_shared_setting_once(package, monkeypatch):
    from symdrive_core.optim import reconstruct

    starts = []
    start = reconstruct.Fit.start
    monkeypatch.setattr(reconstruct.Fit, "start", staticmethod(lambda m, cfg: starts.append(cfg) or start(m, cfg)))
    settings = bench.reconstruction_settings(package, 20)
    rows = run_settings(settings, progress=False)
    assert {r["knob"] for r in rows} == {"resolution schedule", "densify until"}
    assert all(sum(r["default"] for r in rows if r["knob"] == k) == 1 for k in {r["knob"] for r in rows})
    assert len(starts) == len({repr(c) for c in starts}) == 3  # full resolution, coarse to fine, densify until 0.3
    full = next(r for r in rows if r["value"] == "full resolution")
    assert full["default"] and full["psnr"] == next(r["psnr"] for r in rows if r["default"] and r["knob"] == "densify until")


def test_a_fit_is_scored_between_segments_as_its_end_is(tmp_path):
    """Through each camera's colour transform and with the vehicles where the fit placed them, as
    ``symdrive reconstruct`` scores its end; the package stays as recorded."""
    root, *_ = write_moving_box(tmp_path / "pkg")
    m = add_camera(root, "right", BASELINE_M, colours=lambda rgb: rgb * [1.12, 1.05, 0.95] + [0.02, 0.0, -0.01])
    recorded = [a.poses for a in m.actors]
    fit = Fit.start(m, ReconstructConfig(iters=200, densify_from=100, densify_every=100, sky_points=0,
                                         actor_points=600, sh_degree=0, lr_exposure=5e-3,
                                         pose_refine=PoseRefineConfig(enabled=True, start_fraction=0.0)))
    fit.train(progress=False)
    assert set(fit.poses()) == {"car_1"}
    got = bench.heldout_scores(m, fit)
    g, actors = fit.gaussians()
    placed = with_refined(copy.deepcopy(m), fit.poses())
    assert got == evaluate_heldout(placed, g, fit.heldout_frames, actors=actors, exposure=fit.exposure.by_camera())
    raw = evaluate_heldout(m, g, fit.heldout_frames, actors=actors)["cameras"]
    assert got["cameras"]["right"]["psnr_heldout"] > raw["right"]["psnr_heldout"] + 1.0
    assert [a.poses for a in m.actors] == recorded
