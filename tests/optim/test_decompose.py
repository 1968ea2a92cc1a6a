"""Decomposed reconstruction on a tiny scene whose truth is known: a two-coloured box driving
over a textured floor in front of a wall, faster than the camera that records it."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from symdrive_core import conventions
from symdrive_core.eval.views import evaluate_heldout, recorded_renderer
from symdrive_core.gaussians import Gaussians
from symdrive_core.metrics import psnr
from symdrive_core.optim import decompose
from symdrive_core.optim.reconstruct import Part, ReconstructConfig, reconstruct, view_pool
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


def _seen_surface(frames=(0, 1), n=40, seed=0):
    """A vehicle box at two frames metres and degrees apart, photographed with a depth map: points
    inside it (each its own colour), road under its wheels and a wall beside it. Returns the track,
    the views (frame, K, world_to_camera, image, depth) and, per colour, the inside points'
    local coordinates."""
    from symdrive_core.rotations import quat_from_yaw

    rng = np.random.default_rng(seed)
    half = 0.5 * WLH[[1, 0, 2]]
    poses = [Pose(np.array([1.0 + 2.5 * f, 8.0, half[2]]), quat_from_yaw(0.3 * f)) for f in frames]
    track = decompose.Track("car_1", 1, WLH, poses)
    K = conventions.intrinsics_from_fov(320, 240, np.deg2rad(70))
    views, truth = [], {}
    for f, pose in zip(frames, poses):
        inside = rng.uniform(-0.8, 0.8, (n, 3)) * half  # clear of the box's walls by more than a pixel
        inside[:, 2] = np.maximum(inside[:, 2], -half[2] + 2 * decompose.ROAD_LAYER_M)
        road = np.column_stack([rng.uniform(-0.8, 0.8, (n, 2)) * half[:2], np.full(n, -half[2] + 0.02)])
        wall = inside + np.array([0.0, 3.0 * half[1], 0.0])
        local = np.concatenate([inside, road, wall])
        w2c = conventions.invert_rigid(look_at_c2w((2.5 * f, 0.0, 1.5), pose.translation))
        uv, z = conventions.project_points(pose.apply(local), w2c, K)
        px = np.floor(uv).astype(int)
        image, depth = np.zeros((240, 320, 3)), np.full((240, 320), np.nan, np.float32)
        depth[5, 5] = np.inf  # the sky and an unmeasured pixel count as nothing
        for k, ((u, v), zk) in enumerate(zip(px, z)):
            if np.isfinite(depth[v, u]):  # one point a pixel
                continue
            colour = np.array([(k + 1) / 256.0, f / 4.0, 0.5])
            image[v, u], depth[v, u] = colour, zk
            if k < n:
                truth[(k + 1, f)] = local[k]
        views.append((f, K, w2c, image, depth))
    return track, views, truth


def test_measured_points_carry_each_return_into_the_vehicle_by_its_own_frame():
    """Returns inside the box at their own frame come back in the vehicle's frame where its
    surface is (within a pixel's footprint), each with its pixel's colour, though the box moved
    3 m and turned 17 degrees between the frames; the road under it, a wall beside it and
    unmeasured pixels do not."""
    track, views, truth = _seen_surface()
    pts, cols = decompose.measured_points(track, views)
    assert len(pts) == len(truth) > 70
    for p, c in zip(pts, cols):
        key = (round(c[0] * 256.0), round(c[1] * 4.0))
        assert np.linalg.norm(p - truth[key]) < 0.03, (key, p, truth[key])  # a pixel at 9 m is 3 cm


def test_measured_points_skip_frames_the_vehicle_is_not_in_and_views_without_depth():
    track, views, truth = _seen_surface()
    absent = decompose.Track("car_1", 1, WLH, [track.poses[0], None])
    assert len(decompose.measured_points(absent, views)[0]) == sum(f == 0 for _, f in truth)
    no_depth = [(f, K, w2c, image, None) for f, K, w2c, image, _ in views]
    assert len(decompose.measured_points(track, no_depth)[0]) == 0


def test_a_vehicle_starts_on_its_measured_surface_then_its_box():
    """With fewer returns than start points the vehicle keeps every return (in its colour) and
    fills up on its box's faces; with more it keeps a random subset of the returns alone."""
    from symdrive_core.optim.reconstruct import vehicle_start
    from symdrive_core.optim.views import View

    track, seen, truth = _seen_surface()
    views = [View(f, torch.from_numpy(K).float(), torch.from_numpy(w2c).float(), torch.from_numpy(image).float(),
                  torch.from_numpy(depth), 320, 240, "front") for f, K, w2c, image, depth in seen]
    rng = np.random.default_rng(0)
    g = vehicle_start(track, views, 200, rng)
    measured_pts, measured_cols = decompose.measured_points(track, seen)
    m = len(measured_pts)
    assert len(g) == 200 and m == len(truth)
    np.testing.assert_allclose(g.means[:m], measured_pts, atol=1e-5)  # float32 views
    np.testing.assert_allclose(g.base_colors[:m], measured_cols, atol=1e-5)
    faces = g.means[m:] / track.half
    assert np.allclose(np.abs(faces).max(1), 0.95, atol=1e-5)  # on the faces, 5 % inside
    np.testing.assert_allclose(g.opacities, 0.5, atol=1e-6)
    few = vehicle_start(track, views, 30, rng)
    assert len(few) == 30
    assert all(np.linalg.norm(measured_pts - p, axis=1).min() < 1e-5 for p in few.means)


def test_a_loose_box_leaves_to_the_background_what_it_draws(tmp_path, monkeypatch):
    """A tracked box half as long and wide again as its car, on a plain street: the slack's
    Gaussians start in the street's colour and draw it as well as the background behind them, so
    only the coverage cost tells them apart. With it the vehicle leaves the street to the
    background (less of the vehicle where the car is not) and still draws the car, at a
    small cost on its pixels."""
    from dataclasses import replace

    from tests.optim import moving_box

    plain = moving_box.street()
    plain = Gaussians.from_activated(plain.means, plain.quats, plain.scales, plain.opacities,
                                     np.tile([0.55, 0.6, 0.5], (len(plain), 1)))
    monkeypatch.setattr(moving_box, "street", lambda: plain)
    root, _, truth, heldout = moving_box.write_moving_box(tmp_path / "pkg")
    m = load_manifest(root)
    m.actors[0] = replace(m.actors[0], wlh=WLH * np.array([1.5, 1.5, 1.0]))
    m.save(root / "manifest.json")
    m = load_manifest(root)
    base = ReconstructConfig(iters=600, densify_from=100, densify_every=100, sky_points=0, actor_points=600,
                             checkpoint_every=10_000, sh_degree=0)
    outside, car = {}, {}
    for w in (0.0, 0.03):
        r = reconstruct(m, tmp_path / f"w{w}", replace(base, vehicle_alpha_weight=w), progress=False)
        bg, actor = (GaussianTensors.from_gaussians(g) for g in (r.gaussians, r.actors["car_1"]))
        spill, score = [], []
        for i in heldout:
            with torch.no_grad():
                out = render_scene(bg, [(actor, moving_box.box_pose(i), 1)], CameraView.of_frame(m.cameras[0], i))
            spill.append(out["instance"][..., 0].numpy()[~truth[i]["mask"]].sum())
            score.append(_masked_psnr(out["rgb"].clamp(0, 1).numpy(), truth[i]["rgb"], truth[i]["mask"]))
        outside[w], car[w] = sum(spill), np.mean(score)
    assert outside[0.03] < 0.5 * outside[0.0], (outside, car)  # measured: 459 to 137 pixels' worth
    assert car[0.03] > car[0.0] - 1.5, (outside, car)  # 33.3 and 32.0 dB


def test_the_coverage_cost_reaches_the_fit_from_the_command_line(tmp_path, command_config):
    """``--vehicle-alpha-weight`` sets the config's weight (off when not given); a negative or
    non-finite weight is refused before any fitting."""
    from symdrive_core.cli import main
    from tests.optim.moving_box import write_moving_box

    root, *_ = write_moving_box(tmp_path / "pkg")
    seen = [command_config([str(root), "--quiet", *extra]).vehicle_alpha_weight
            for extra in ([], ["--vehicle-alpha-weight", "0.02"])]
    assert seen == [ReconstructConfig().vehicle_alpha_weight, 0.02] and seen[0] == 0.0
    for bad in ("-0.1", "nan", "inf"):
        with pytest.raises(SystemExit) as exit_:
            main(["reconstruct", str(root), "--vehicle-alpha-weight", bad])
        assert exit_.value.code == 2


def _part(name: str, poses) -> Part:
    return Part(name, {}, None, None, 1.0, None, None, poses=poses)


def test_views_of_a_driving_vehicle_come_as_often_as_configured(moving_box):
    """``driving_view_repeat``: one pass over the views holds each view once, and each view whose
    frame shows a vehicle that drives that many times; a parked vehicle repeats nothing, and a box
    that moves less than ``driving_m`` is parked."""
    from symdrive_core.optim.views import load_views

    root, *_ = moving_box
    m = load_manifest(root)
    views = load_views(m, list(range(len(m.frames))), depth=False)
    (track,) = decompose.tracks(m)
    n = len(track.poses)
    seen = [p if 5 <= f <= 8 else None for f, p in enumerate(track.poses)]  # drives 2.7 m while seen
    parts = [_part("background", None), _part("car", seen), _part("parked", [track.poses[0]] * n)]
    for repeat in (1, 2, 3):
        counts = np.bincount(view_pool(views, parts, ReconstructConfig(driving_view_repeat=repeat)), minlength=len(views))
        assert counts.tolist() == [repeat if 5 <= v.frame <= 8 else 1 for v in views], repeat
    slow = ReconstructConfig(driving_view_repeat=2, driving_m=3.0)
    assert view_pool(views, parts, slow).tolist() == list(range(len(views)))


def test_a_fit_draws_each_pass_from_the_pool(moving_box, tmp_path, monkeypatch):
    """The training loop renders one pass's views as :func:`view_pool` lists them: with
    ``driving_view_repeat`` 2 and the box seen at frames 4 to 9 only, a pass renders those training
    views twice and the others once."""
    from symdrive_core.optim import reconstruct as fitting
    from symdrive_core.scene.ground_truth import split_frames

    root, *_ = moving_box
    m = load_manifest(root)
    (box,) = m.actors
    box.poses = [p if 4 <= f <= 9 else None for f, p in enumerate(box.poses)]
    box.recorded_poses = None
    train = split_frames(m)[0]
    expected = sorted(train + [f for f in train if 4 <= f <= 9])
    rendered = []
    render = fitting.render_parts

    def recording(parts, view, *args, **kwargs):
        rendered.append(view.frame)
        return render(parts, view, *args, **kwargs)

    monkeypatch.setattr(fitting, "render_parts", recording)
    cfg = ReconstructConfig(iters=len(expected), densify_from=10_000, sky_points=0, checkpoint_every=10_000,
                            sh_degree=0, driving_view_repeat=2)
    reconstruct(m, tmp_path / "fit", cfg, progress=False)
    assert sorted(rendered) == expected and len(expected) > len(train)


def test_the_driving_views_repeat_reaches_the_fit_from_the_command_line(tmp_path, command_config):
    """``--driving-view-repeat`` sets the config's count (once, the default, when not given); a count
    below 1 is refused before any fitting."""
    from symdrive_core.cli import main
    from tests.optim.moving_box import write_moving_box

    root, *_ = write_moving_box(tmp_path / "pkg")
    seen = [command_config([str(root), "--quiet", *extra]).driving_view_repeat
            for extra in ([], ["--driving-view-repeat", "2"])]
    assert seen == [ReconstructConfig().driving_view_repeat, 2] and seen[0] == 1
    with pytest.raises(SystemExit) as exit_:
        main(["reconstruct", str(root), "--driving-view-repeat", "0"])
    assert exit_.value.code == 2
