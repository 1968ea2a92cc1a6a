"""Decomposed reconstruction on a tiny scene whose truth is known: a two-coloured box driving
over a textured floor in front of a wall, faster than the camera that records it."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from symdrive_core import conventions
from symdrive_core.eval.views import evaluate_heldout, recorded_renderer
from symdrive_core.metrics import psnr
from symdrive_core.optim import decompose
from symdrive_core.optim.reconstruct import ReconstructConfig, reconstruct
from symdrive_core.scene import Pose, load_manifest
from symdrive_core.scene.camera import CameraView
from symdrive_core.splat.render import render_scene
from symdrive_core.splat.tensors import GaussianTensors
from tests.conftest import look_at_c2w
from tests.optim.moving_box import WLH, H, W


@pytest.fixture(scope="module")
def fits(moving_box, tmp_path_factory):
    """The shared small-budget decomposed fit, and a static one with the same budget."""
    root, decomposed, *_ = moving_box
    m = load_manifest(root)
    static_cfg = ReconstructConfig(iters=600, densify_from=100, densify_every=100, sky_points=0, checkpoint_every=10_000,
                                   sh_degree=0, decompose=False)
    return m, decomposed, reconstruct(m, tmp_path_factory.mktemp("fits") / "static", static_cfg, progress=False)


def _masked_psnr(pred, gt, mask):
    return psnr(pred[mask], gt[mask])


def test_the_moving_box_is_sharper_decomposed_than_static(moving_box, fits):
    _, _, truth, _, heldout = moving_box
    m, decomposed, static = fits
    assert set(decomposed.actors) == {"car_1"} and static.actors == {}
    render_d = _renderer(m, decomposed)
    render_s = _renderer(m, static)
    car_d, car_s, rest_d, rest_s = [], [], [], []
    for i in heldout:
        t = truth[i]
        pd, ps = render_d(i), render_s(i)
        car_d.append(_masked_psnr(pd, t["rgb"], t["mask"]))
        car_s.append(_masked_psnr(ps, t["rgb"], t["mask"]))
        rest_d.append(_masked_psnr(pd, t["rgb"], ~t["mask"]))
        rest_s.append(_masked_psnr(ps, t["rgb"], ~t["mask"]))
    assert np.mean(car_d) > np.mean(car_s) + 3.0, (car_d, car_s)
    assert np.mean(rest_d) > np.mean(rest_s) - 0.5, (rest_d, rest_s)
    score = evaluate_heldout(m, decomposed.gaussians, heldout, actors=decomposed.actors)["psnr_heldout"]
    assert score > evaluate_heldout(m, static.gaussians, heldout)["psnr_heldout"]


def test_the_box_is_learnt_in_its_own_frame(moving_box, fits):
    """Seen alone from views around it that no frame recorded, the fitted box looks like the truth."""
    box = moving_box[3]
    _, decomposed, _ = fits
    fitted, true = GaussianTensors.from_gaussians(decomposed.actors["car_1"]), GaussianTensors.from_gaussians(box)
    K = conventions.intrinsics_from_fov(W, H, np.deg2rad(60))
    scores, overlap = [], []
    for yaw in (-0.5, 0.0, 0.5):  # the side the camera saw, from three angles
        eye = 6.0 * np.array([np.sin(yaw), -np.cos(yaw), 0.15])
        view = CameraView(conventions.invert_rigid(look_at_c2w(eye, (0, 0, 0))), K, W, H)
        with torch.no_grad():
            a = render_scene(None, [(fitted, Pose.identity(), 1)], view)
            b = render_scene(None, [(true, Pose.identity(), 1)], view)
        mask, fitted_mask = b["alpha"][..., 0].numpy() > 0.5, a["alpha"][..., 0].numpy() > 0.5
        scores.append(_masked_psnr(a["rgb"].clamp(0, 1).numpy(), b["rgb"].clamp(0, 1).numpy(), mask))
        overlap.append((mask & fitted_mask).sum() / (mask | fitted_mask).sum())
    assert min(scores) > 15.0 and min(overlap) > 0.85, (scores, overlap)  # half the box lost: about 8 dB
    local = decomposed.actors["car_1"].means.astype(np.float64)
    assert decompose.inside_box(local, 0.5 * WLH[[1, 0, 2]]).all()


def test_the_background_does_not_absorb_the_box(moving_box, fits):
    """The background alone is the scene without the box (where frames saw the floor), and holds
    nothing inside the volume the box swept."""
    _, _, truth, _, heldout = moving_box
    m, decomposed, static = fits
    t = decompose.tracks(m)
    assert not decompose.in_swept_boxes(decomposed.gaussians.means, t).any()
    assert decompose.in_swept_boxes(static.gaussians.means, t).sum() > 20  # the static fit smears it in
    gains = []
    for i in heldout:
        view = CameraView.of_frame(m.cameras[0], i)
        region = truth[i]["mask"]
        with torch.no_grad():
            only_d = render_scene(GaussianTensors.from_gaussians(decomposed.gaussians), [], view)["rgb"].numpy()
            only_s = render_scene(GaussianTensors.from_gaussians(static.gaussians), [], view)["rgb"].numpy()
        gains.append(_masked_psnr(only_d.clip(0, 1), truth[i]["background"], region)
                     - _masked_psnr(only_s.clip(0, 1), truth[i]["background"], region))
    assert np.mean(gains) > 2.0, gains


def _renderer(m, result):
    render = recorded_renderer(m, result.gaussians, result.actors)
    return lambda i: render(CameraView.of_frame(m.cameras[0], i), i)


def test_the_command_links_each_recorded_vehicle(tmp_path, capsys):
    """``symdrive reconstruct`` points each fitted vehicle's ``assets.splats`` at its PLY;
    ``--static`` fits none and leaves the vehicles without assets."""
    import json

    from symdrive_core.cli import main
    from tests.optim.moving_box import write_moving_box

    root, *_ = write_moving_box(tmp_path / "pkg")
    static = tmp_path / "static"
    assert main(["reconstruct", str(root), "--iters", "30", "--static", "--out", str(static), "--quiet"]) == 0
    assert "actors" not in json.loads(capsys.readouterr().out) and not (static / "actors").exists()
    assert load_manifest(root).actor("car_1").splats is None
    assert main(["reconstruct", str(root), "--iters", "30", "--quiet"]) == 0
    summary = json.loads(capsys.readouterr().out)
    m = load_manifest(root)
    assert summary["actors"]["car_1"]["gaussians"] > 100 and "heldout" in summary
    assert m.actor("car_1").splats == "reconstruction/actors/car_1.ply" and m.background_splats
