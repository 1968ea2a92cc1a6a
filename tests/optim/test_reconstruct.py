import json

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.eval.views import evaluate_heldout
from symdrive_core.io.ply import read_splats
from symdrive_core.optim.reconstruct import (
    Checkpoint,
    ReconstructConfig,
    initial_gaussians,
    knn_scale,
    load_views,
    reconstruct,
    scene_extent,
)
from symdrive_core.scene import load_manifest
from symdrive_core.scene.ground_truth import split_frames


def _cfg(**kw):
    base = {"iters": 150, "densify_from": 40, "densify_every": 40, "checkpoint_every": 50, "sky_points": 0}
    base.update(kw)
    return ReconstructConfig(**base)


def test_training_beats_the_initialisation_on_heldout_frames(synthetic_package, tmp_path):
    root, _ = synthetic_package
    m = load_manifest(root)
    cfg = _cfg()
    init = initial_gaussians(m, load_views(m, split_frames(m)[0]), cfg)
    before = evaluate_heldout(m, init)["psnr_heldout"]
    result = reconstruct(m, tmp_path / "out", cfg, progress=False)
    after = evaluate_heldout(m, result.gaussians)["psnr_heldout"]
    assert after > before + 3.0, (before, after)
    assert after > 24.0
    on_disk = json.loads((tmp_path / "out/metrics.json").read_text())
    assert on_disk == result.metrics and on_disk["seconds_per_iteration"] > 0
    assert on_disk["heldout_frames"] == split_frames(m)[1] and "heldout" not in on_disk  # scoring is the caller's
    assert len(read_splats(tmp_path / "out/background.ply")) == len(result.gaussians)
    assert result.metrics["densify"], "density control never ran"


def test_resume_continues_from_the_checkpoint(synthetic_package, tmp_path):
    root, _ = synthetic_package
    m = load_manifest(root)
    first = reconstruct(m, tmp_path, _cfg(iters=60, checkpoint_every=30), progress=False)
    extent, _ = scene_extent(load_views(m, split_frames(m)[0]))
    params, opt, _stats, it = Checkpoint(tmp_path / "checkpoint").load(_cfg(), extent)
    assert it == 60 and len(params["means"]) == len(first.gaussians)
    steps = {g["name"]: float(opt.state[g["params"][0]]["step"]) for g in opt.param_groups
             if g["params"][0] in opt.state}  # shN has no state while SH degree 0 is active
    assert set(steps.values()) == {60.0} and {"means", "sh0", "opacity_logits"} <= set(steps)
    assert np.allclose(params["means"].detach().numpy(), first.gaussians.means)
    second = reconstruct(m, tmp_path, _cfg(iters=80), resume=True, progress=False)
    assert second.metrics["resumed_from"] == 60 and second.metrics["iterations"] == 80


def test_a_resume_with_other_options_or_a_torn_checkpoint_is_refused_naming_it(synthetic_package, tmp_path):
    from symdrive_core.errors import InputError
    from symdrive_core.io.ply import write_splats

    root, _ = synthetic_package
    m = load_manifest(root)
    reconstruct(m, tmp_path, _cfg(iters=60, checkpoint_every=30), progress=False)
    for cfg, says in ((_cfg(iters=40), "iteration 60, past this run's 40"),
                      (_cfg(iters=80, sh_degree=0), "sh_degree = 1, this run asks 0"),
                      (_cfg(iters=80, decompose=False), "decompose = True, this run asks False"),
                      (_cfg(iters=80, seed=3), "seed = 0, this run asks 3")):
        with pytest.raises(InputError, match=says):
            reconstruct(m, tmp_path, cfg, resume=True, progress=False)
    g = read_splats(tmp_path / "checkpoint" / "gaussians.ply")
    write_splats(tmp_path / "checkpoint" / "gaussians.ply", g.subset(np.arange(len(g) - 1)))  # a kill between writes
    with pytest.raises(InputError, match=f"state of {len(g)} Gaussians, gaussians.ply {len(g) - 1}"):
        reconstruct(m, tmp_path, _cfg(iters=80), resume=True, progress=False)


def test_depth_loss_runs_and_keeps_quality(synthetic_package, tmp_path):
    root, _ = synthetic_package
    m = load_manifest(root)
    result = reconstruct(m, tmp_path, _cfg(iters=80, depth_weight=0.1, sh_degree=0), progress=False)
    assert np.isfinite(evaluate_heldout(m, result.gaussians)["psnr_heldout"]) and result.gaussians.sh_degree == 0


def test_cli_links_the_result_into_the_package(synthetic_package, tmp_path, capsys):
    import shutil

    src, _ = synthetic_package
    root = tmp_path / "pkg"
    shutil.copytree(src, root)
    assert main(["reconstruct", str(root), "--iters", "20", "--lateral"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["gaussians"] > 0 and [r["offset_m"] for r in summary["lateral"]] == [-0.5, 0.5]
    m = load_manifest(root)
    assert m.background_splats == "reconstruction/background.ply"
    assert (root / m.background_splats).exists()


def test_missing_point_cloud_is_a_clear_error(synthetic_package, tmp_path):
    from symdrive_core.errors import InputError

    root, _ = synthetic_package
    m = load_manifest(root)
    m.background_points = None
    with pytest.raises(InputError, match="background.points"):
        reconstruct(m, tmp_path, _cfg(iters=5), progress=False)


def test_fit_needs_initial_gaussians_or_a_checkpoint(synthetic_package, tmp_path):
    from symdrive_core.optim.reconstruct import fit

    root, _ = synthetic_package
    m = load_manifest(root)
    views = load_views(m, split_frames(m)[0])
    with pytest.raises(ValueError, match="no initial Gaussians"):
        fit(views, None, _cfg(), checkpoint=Checkpoint(tmp_path / "none"), resume=True, progress=False)


@pytest.mark.parametrize("origin", [(0.0, 0.0, 0.0), (1.0e3, -2.0e3, 0.0), (5.0e5, 4.5e6, 30.0)])
def test_initial_scales_do_not_depend_on_where_the_origin_is(origin):
    """Points 4 to 9 cm apart, at the origin, a kilometre away and at UTM coordinates: the scales
    match a float64 brute-force oracle (float32 distances cancelled to the 1e-4 floor there)."""
    rng = np.random.default_rng(0)
    local = np.stack(np.meshgrid(*(np.arange(6) * 0.07,) * 3), -1).reshape(-1, 3) + rng.uniform(-0.015, 0.015, (216, 3))
    d2 = ((local[:, None] - local[None]) ** 2).sum(-1)
    oracle = np.sqrt(np.sort(d2, axis=1)[:, 1:4].mean(1))
    np.testing.assert_allclose(knn_scale(local + np.array(origin)), oracle, rtol=1e-5)
