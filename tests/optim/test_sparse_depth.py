"""Sparse depth in the reconstruction: gaps are unmeasured, not sky (no sky dome seeded there), and
the depth loss is the inverse-depth L1 at the measured pixels only."""

import shutil

import numpy as np
import pytest
import torch

from symdrive_core.eval.views import evaluate_heldout
from symdrive_core.io.images import read_image, write_image
from symdrive_core.io.points import read_points
from symdrive_core.optim.reconstruct import ReconstructConfig, depth_loss, load_views, reconstruct, sky_points
from symdrive_core.scene import load_manifest
from symdrive_core.scene.ground_truth import split_frames


@pytest.fixture(scope="module")
def sparse_package(synthetic_package, tmp_path_factory):
    """The synthetic package with 5% of each depth map kept (0 elsewhere), declared unmeasured."""
    src, _ = synthetic_package
    root = tmp_path_factory.mktemp("sparse") / "pkg"
    shutil.copytree(src, root)
    m = load_manifest(root)
    rng = np.random.default_rng(0)
    cam = m.cameras[0]
    for i, cf in enumerate(cam.frames):
        d = read_image(m.resolve(cf.depth))[..., 0]
        keep = rng.random(d.shape) < 0.05
        write_image(root / f"sparse/{i:03d}.exr", np.where(keep, d, 0.0).astype(np.float32), dtype="float")
        cf.depth = f"sparse/{i:03d}.exr"
    cam.depth_zero = "unmeasured"
    m.save()
    return root


def test_gaps_in_sparse_depth_seed_no_sky(sparse_package):
    m = load_manifest(sparse_package)
    views = load_views(m, split_frames(m)[0])
    gaps = sum(int(np.isnan(v.depth.numpy()).sum()) for v in views)
    assert gaps > 0.9 * sum(v.width * v.height for v in views)
    pts, _ = sky_points(views, 1000, 100.0, np.random.default_rng(0))
    assert len(pts) == 0
    cloud = read_points(m.resolve(m.background_points))[0]  # sparse sensor depth: no skyline estimate either
    assert len(sky_points(views, 1000, 100.0, np.random.default_rng(0), cloud)[0]) == 0
    m.cameras[0].depth_zero = "sky"  # the same files read the way dense maps are: gaps become sky
    pts, _ = sky_points(load_views(m, split_frames(m)[0]), 1000, 100.0, np.random.default_rng(0))
    assert len(pts) == 1000
    eye = m.cameras[0].frames[0].camera_to_world[:3, 3]
    assert np.linalg.norm(pts - eye, axis=1).min() > 95.0  # on the sphere around some camera


def test_depth_loss_is_inverse_depth_l1_at_measured_pixels_only():
    target = torch.tensor([[2.0, float("nan"), float("inf")], [4.0, 0.5, 8.0]])
    pred = torch.tensor([[2.5, 9.0, 9.0], [3.0, 0.4, 7.0]], dtype=torch.float32, requires_grad=True)
    alpha = torch.tensor([[1.0, 1.0, 1.0], [1.0, 0.9, 0.2]])  # the last pixel: render too transparent
    loss = depth_loss({"depth": pred[..., None]}, alpha[..., None], target)
    p, t = np.array([2.5, 3.0, 0.4]), np.array([2.0, 4.0, 0.5])
    oracle = np.mean(np.abs(1 / p - 1 / t))  # float64
    assert float(loss.detach()) == pytest.approx(oracle, rel=1e-6)
    loss.backward()
    grad = pred.grad.numpy()
    assert np.all(grad[[0, 0, 1], [1, 2, 2]] == 0) and np.all(grad[[0, 1, 1], [0, 0, 1]] != 0)
    nothing = torch.full((2, 3), float("nan"))
    assert depth_loss({"depth": pred[..., None]}, alpha[..., None], nothing) is None


def test_sparse_depth_supervision_improves_heldout_depth(sparse_package, tmp_path):
    """5% of the pixels measured: the held-out frames' rendered inverse depth moves towards the
    dense truth (measured 0.0088 -> 0.0063 at 60 iterations), colour quality kept."""
    from symdrive_core.scene.camera import CameraView
    from symdrive_core.splat.render import SplatRenderer

    m = load_manifest(sparse_package)
    cam = m.cameras[0]
    heldout = split_frames(m)[1]
    errors, psnr = {}, {}
    for weight in (0.0, 0.5):
        cfg = ReconstructConfig(iters=60, densify_from=40, densify_every=40, checkpoint_every=60, sky_points=0,
                                depth_weight=weight, sh_degree=0)
        result = reconstruct(m, tmp_path / str(weight), cfg, progress=False)
        render = SplatRenderer(result.gaussians)
        err = []
        for i in heldout:
            pred = render.depth(CameraView.of_frame(cam, i), 0.5)
            truth = read_image(sparse_package / f"depth/{i:03d}.exr")[..., 0].astype(np.float64)
            ok = (truth > 0) & (pred > 0)
            err.append(np.mean(np.abs(1 / pred[ok] - 1 / truth[ok])))
        errors[weight], psnr[weight] = np.mean(err), evaluate_heldout(m, result.gaussians)["psnr_heldout"]
    assert errors[0.5] < 0.85 * errors[0.0], errors
    assert psnr[0.5] > psnr[0.0] - 1.5, psnr


def test_lidar_depth_turns_the_depth_loss_on_by_default(sparse_package, synthetic_package, tmp_path):
    """By default the loss runs on a sensor's sparse depth (``depth_zero: unmeasured``) and not on
    other depth maps; a weight given explicitly wins either way."""
    tiny = dict(iters=2, densify_from=40, checkpoint_every=60, sky_points=0, sh_degree=0)
    lidar = ReconstructConfig().sensor_depth_weight
    assert lidar > 0
    cases = [(sparse_package, None, lidar), (synthetic_package[0], None, 0.0), (sparse_package, 0.0, 0.0),
             (synthetic_package[0], 0.2, 0.2)]
    for k, (root, given, expected) in enumerate(cases):
        cfg = ReconstructConfig(**tiny, depth_weight=given)
        assert cfg.depth_weight_for(load_manifest(root).cameras[0]) == expected
        result = reconstruct(load_manifest(root), tmp_path / str(k), cfg, progress=False)
        assert result.metrics["depth_weight"] == expected


def test_a_sensors_depth_gets_a_broad_dome_that_keeps_its_places_and_sizes(sparse_package, tmp_path):
    """Sparse sensor depth: the dome starts above the horizon and the points' skyline as broad
    Gaussians (one standard deviation ``sensor_dome_deg`` across), which keep their places and sizes
    through the fit and its resumption, learn their colours, and end in the background."""
    from dataclasses import replace

    from symdrive_core.io.points import write_points
    from symdrive_core.optim.config import SkyConfig
    from symdrive_core.optim.reconstruct import dome_radius, sensor_dome

    root = tmp_path / "pkg"  # a scanner's returns stop at its top beam: none above 2.5 m
    shutil.copytree(sparse_package, root)
    pts, cols = read_points(root / "points.ply")
    write_points(root / "points.ply", pts[pts[:, 2] < 2.5], cols[pts[:, 2] < 2.5])
    m = load_manifest(root)
    views = load_views(m, split_frames(m)[0])
    cfg = ReconstructConfig(iters=40, densify_from=10, densify_every=10, checkpoint_every=20, sky_points=300,
                            sh_degree=0)
    dome = sensor_dome(m, views, cfg)
    assert dome is not None and 0 < len(dome) <= 300
    radius = dome_radius(views)
    np.testing.assert_allclose(dome.scales, radius * np.tan(np.radians(cfg.sky.sensor_dome_deg)), rtol=1e-5)
    assert sensor_dome(m, views, replace(cfg, sky=SkyConfig(sensor_dome_deg=0.0))) is None
    m.cameras[0].depth_zero = "sky"  # dense depth marks its own sky: no sensor dome
    assert sensor_dome(m, load_views(m, split_frames(m)[0]), cfg) is None

    m = load_manifest(root)
    reconstruct(m, tmp_path / "fit", replace(cfg, iters=20), progress=False)
    result = reconstruct(m, tmp_path / "fit", cfg, resume=True, progress=False)
    started = {tuple(p): i for i, p in enumerate(dome.means)}
    kept = [(j, started[tuple(p)]) for j, p in enumerate(result.gaussians.means) if tuple(p) in started]
    assert len(kept) > 0.5 * len(dome)  # what stayed is where it started, as large, and coloured anew
    j, i = map(list, zip(*kept))
    np.testing.assert_array_equal(result.gaussians.log_scales[j], dome.log_scales[i])
    np.testing.assert_array_equal(result.gaussians.quats[j], dome.quats[i])
    assert not np.array_equal(result.gaussians.sh[j], dome.sh[i])
    assert (tmp_path / "fit/checkpoint/sky/gaussians.ply").exists() and not result.actors
