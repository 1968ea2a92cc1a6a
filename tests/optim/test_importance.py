"""Each Gaussian's summed blending weight, and the pruning of the least of them when density control ends."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch

from symdrive_core import conventions
from symdrive_core.optim import importance
from symdrive_core.optim.reconstruct import (
    Part,
    ReconstructConfig,
    fit,
    fit_parts,
    initial_gaussians,
    load_views,
    scene_extent,
)
from symdrive_core.optim.views import View
from symdrive_core.scene import Pose, load_manifest
from symdrive_core.scene.ground_truth import split_frames
from symdrive_core.splat.compose import rotate_quats
from symdrive_core.splat.oracle import render_oracle
from tests.conftest import look_at_c2w

W, H = 40, 24


def _params(rng, n, centre):
    """Raw float64 parameters (the optimiser's layout) of ``n`` overlapping Gaussians around ``centre``."""
    q = rng.normal(size=(n, 4))
    return {"means": torch.tensor(centre + rng.normal(scale=0.6, size=(n, 3))),
            "quats": torch.tensor(q / np.linalg.norm(q, axis=1, keepdims=True)),
            "log_scales": torch.tensor(np.log(rng.uniform(0.1, 0.5, size=(n, 3)))),
            "opacity_logits": torch.tensor(rng.normal(1.0, 1.5, size=n)),
            "sh0": torch.tensor(rng.uniform(-1, 1, size=(n, 1, 3)))}


def _view(frame, eye):
    c2w = look_at_c2w(eye, (eye[0], 6.0, 1.0))
    K = conventions.intrinsics_from_fov(W, H, np.deg2rad(60))
    return View(frame, torch.tensor(K, dtype=torch.float32),
                torch.tensor(conventions.invert_rigid(c2w), dtype=torch.float32),
                torch.zeros(H, W, 3, dtype=torch.uint8), None, W, H, "front")


def _world(params, pose):
    """The part's Gaussians placed in the world, activated, float64, as the oracle takes them."""
    means, quats = params["means"], params["quats"]
    if pose is not None:
        R = torch.tensor(pose.R, dtype=torch.float32).double()  # a layer's rotation is float32
        means = means @ R.T + torch.tensor(pose.translation)
        quats = rotate_quats(R, quats)
    return means, quats, params["log_scales"].exp(), torch.sigmoid(params["opacity_logits"])


def _part(name, params, poses=None):
    return Part(name, params, None, None, 1.0, None, None, poses=poses)


def test_blending_weights_are_the_oracles_weights_summed_over_every_pixel_of_every_view():
    """Against the float64 pixel-outer oracle rendering each Gaussian in a channel of its own (so
    channel i is alpha_i T_i at each pixel): a background and a vehicle present at one of the two
    frames, placed by its pose there; the vehicle's Gaussians count only where it is present."""
    rng = np.random.default_rng(3)
    background = _part("background", _params(rng, 14, np.array([0.0, 6.0, 1.0])))
    c, s = np.cos(0.4), np.sin(0.4)
    pose = Pose.from_matrix([[c, -s, 0, 0.5], [s, c, 0, 4.0], [0, 0, 1, 0.8], [0, 0, 0, 1]])
    car = _part("car", _params(rng, 6, np.zeros(3)), poses=[None, pose])
    views = [_view(0, (0.0, 0.0, 1.5)), _view(1, (0.6, 0.3, 1.4))]
    got = importance.blending_weights([background, car], views, degree=0)
    want = [np.zeros(14), np.zeros(6)]
    for v in views:
        placed = [(background, None)] + ([(car, pose)] if v.frame == 1 else [])
        world = [_world(p.params, at) for p, at in placed]
        means, quats, scales, opac = (torch.cat(x) for x in zip(*world, strict=True))
        out = render_oracle(means, quats, scales, opac, np.eye(len(means)), v.viewmat.double(), v.K.double(), W, H)
        sums = out["rgb"].sum((0, 1))
        want[0] += sums[:14]
        if v.frame == 1:
            want[1] += sums[14:]
    assert all(w.min() >= 0 for w in want) and want[0].max() > 1.0 and want[1].max() > 1.0  # both draw
    for g, w in zip(got, want, strict=True):
        np.testing.assert_allclose(g.numpy(), w, rtol=1e-9, atol=1e-9)


def test_the_least_important_are_an_exact_count_ties_by_index():
    w = torch.tensor([3.0, 0.0, 1.0, 0.0, 2.0, 0.0])
    assert importance.least_important(w, 0.5).tolist() == [False, True, False, True, False, True]
    assert importance.least_important(w, 0.34).tolist() == [False, True, False, True, False, False]
    assert not importance.least_important(w, 0.0).any()
    assert importance.least_important(w, 1.0).tolist() == [False, True, True, True, True, True]
    assert not importance.least_important(torch.zeros(0), 1.0).any()


def _background_fit(synthetic_package, **kw):
    root, _ = synthetic_package
    m = load_manifest(root)
    views = load_views(m, split_frames(m)[0])
    cfg = ReconstructConfig(**{"iters": 10, "densify_from": 10_000, "sky_points": 0, "checkpoint_every": 10_000,
                               "sh_degree": 0, **kw})
    return views, initial_gaussians(m, views, cfg), cfg


def test_a_fit_prunes_its_fraction_once_when_density_control_ends(synthetic_package):
    """``importance_prune`` 0.25 at 10 iterations: density control ends at iteration 6, and a
    quarter of the Gaussians go there, those that paint least; off (0) none go."""
    views, init, cfg = _background_fit(synthetic_package, importance_prune=0.25)
    g, log = fit(views, init, cfg, progress=False)
    n = len(init)
    assert log["importance_prune"] == {"background": round(0.25 * n)} and len(g) == n - round(0.25 * n)
    g0, log0 = fit(views, init, replace(cfg, importance_prune=0.0), progress=False)
    assert len(g0) == n and "importance_prune" not in log0


def test_a_fit_in_segments_prunes_where_the_whole_fit_does(synthetic_package):
    """Stopped before iteration 6 and continued, the fit prunes in the second segment; a segment
    that starts past it prunes nothing again."""
    views, init, cfg = _background_fit(synthetic_package, importance_prune=0.25)
    extent, centre = scene_extent(views)
    part, _ = Part.start("background", init, cfg, extent, centre, cfg.densify, None, False)
    first = fit_parts(views, [part], cfg, 0, until=4, progress=False)
    second = fit_parts(views, [part], cfg, 4, until=8, progress=False)
    third = fit_parts(views, [part], cfg, 8, progress=False)
    assert "importance_prune" not in first and "importance_prune" not in third
    assert second["importance_prune"] == {"background": round(0.25 * len(init))}
    assert len(part.params["means"]) == len(init) - round(0.25 * len(init))


def test_the_cli_flag_reaches_the_fit(synthetic_package, tmp_path, capsys):
    import json
    import shutil

    from symdrive_core.cli import main

    src, _ = synthetic_package
    counts = {}
    for name, extra in (("off", []), ("half", ["--importance-prune", "0.5"])):
        root = tmp_path / name
        shutil.copytree(src, root)
        assert main(["reconstruct", str(root), "--iters", "20", "--quiet", "--no-link", *extra]) == 0
        counts[name] = json.loads(capsys.readouterr().out)["gaussians"]
    assert counts["half"] <= 0.55 * counts["off"]
