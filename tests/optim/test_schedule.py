"""The reconstruction's schedules: the image resolution and the SH degree trained at each
iteration, the coarse levels' images and intrinsics, and a resumed fit continuing both."""

import argparse

import numpy as np
import pytest
import torch

from symdrive_core.cli.optim import resolution_schedule_arg
from symdrive_core.optim import reconstruct as rec
from symdrive_core.optim.config import COARSE_TO_FINE, ReconstructConfig
from symdrive_core.optim.views import Levels, View, block_depth, downscaled, held_pixels, load_views
from symdrive_core.scene import load_manifest
from symdrive_core.splat.render import params_from_gaussians, render_params

from .conftest import H, W


def test_downscale_halves_at_each_fraction_of_the_iterations():
    cfg = ReconstructConfig(iters=1000, resolution_schedule=(0.1, 0.3))
    assert [cfg.downscale_at(it) for it in (0, 99, 100, 299, 300, 999)] == [4, 4, 2, 2, 1, 1]
    assert {ReconstructConfig(iters=1000, resolution_schedule=()).downscale_at(it) for it in (0, 500)} == {1}
    with pytest.raises(ValueError, match="schedule_for"):
        ReconstructConfig().downscale_at(0)  # the default depends on the images


def test_the_default_schedule_is_coarse_to_fine_for_large_images_only():
    cfg = ReconstructConfig()
    assert cfg.resolution_schedule is None
    assert cfg.schedule_for(cfg.coarse_to_fine_pixels) == COARSE_TO_FINE == (0.1, 0.3)
    assert cfg.schedule_for(cfg.coarse_to_fine_pixels - 1) == ()
    assert cfg.schedule_for(256 * 144) == () and cfg.schedule_for(613 * 185) == COARSE_TO_FINE  # as measured
    assert ReconstructConfig(resolution_schedule=()).schedule_for(10**7) == ()  # a schedule given stays
    assert resolution_schedule_arg("auto") is None


def test_sh_degree_rises_every_sh_every_iterations_up_to_the_degree():
    cfg = ReconstructConfig(sh_degree=2, sh_every=500)
    assert [cfg.sh_degree_at(it) for it in (0, 499, 500, 999, 1000, 5000)] == [0, 0, 1, 1, 2, 2]


def test_the_command_line_reads_a_schedule():
    assert resolution_schedule_arg("0.1,0.3") == (0.1, 0.3) and resolution_schedule_arg("full") == ()
    for bad in ("0.3,0.1", "0,0.5", "1.5", "a"):
        with pytest.raises(argparse.ArgumentTypeError):
            resolution_schedule_arg(bad)


def test_an_eight_bit_image_is_held_as_uint8_and_read_back_exactly():
    levels = np.random.default_rng(0).integers(0, 256, (4, 6, 3))
    image = (levels / 255.0).astype(np.float32)
    held = held_pixels(image)
    assert held.dtype == torch.uint8
    view = View(0, torch.eye(3), torch.eye(4), held, None, 6, 4, "front")
    assert view.image.dtype == torch.float32 and np.allclose(view.image.numpy(), image, atol=1e-7)
    assert held_pixels(image + 0.1 / 255).dtype == torch.float32  # not 8-bit levels: kept as it is


def test_a_packages_png_frames_are_held_as_uint8(synthetic_package):
    views = load_views(load_manifest(synthetic_package[0]), [0, 2])
    assert all(v.pixels.dtype == torch.uint8 and v.image.shape == (H, W, 3) for v in views)


def test_a_coarse_level_is_the_area_average_with_k_scaled_about_pixel_edges():
    rng = np.random.default_rng(1)
    image = rng.random((9, 13, 3)).astype(np.float32)  # odd sides: the last row and column are cropped
    K = torch.tensor([[10.0, 0, 6.5], [0, 10.0, 4.5], [0, 0, 1]])
    view = View(0, K, torch.eye(4), torch.from_numpy(image), None, 13, 9, "front")
    half = downscaled(view, 2)
    assert (half.width, half.height) == (6, 4) and half.image.shape == (4, 6, 3)
    assert np.allclose(half.image[1, 2].numpy(), image[2:4, 4:6].mean((0, 1)))
    assert np.allclose(half.K.numpy(), [[5.0, 0, 3.25], [0, 5.0, 2.25], [0, 0, 1]])


def test_a_half_resolution_render_with_scaled_k_matches_the_area_averaged_full_render(synthetic_package):
    root, truth = synthetic_package
    m = load_manifest(root)
    view = load_views(m, [0])[0]
    half = downscaled(view, 2)
    params = params_from_gaussians(truth, truth.sh_degree)
    with torch.no_grad():
        full = render_params(params, view.K, view.viewmat, W, H, truth.sh_degree)[0]
        small = render_params(params, half.K, half.viewmat, half.width, half.height, truth.sh_degree)[0]
    pooled = downscaled(View(0, view.K, view.viewmat, full, None, W, H, "front"), 2).image
    shifted = torch.roll(small, 1, dims=1)  # a half-pixel error in K would show as a shift
    assert (small - pooled).abs().mean() < 0.5 * (shifted - pooled)[:, 1:].abs().mean()


def test_a_coarse_depth_block_is_a_surface_sky_or_unmeasured():
    inf, nan = np.inf, np.nan
    d = torch.tensor([[2.0, 4.0, inf, inf, 2.0, inf, nan, nan],
                      [nan, nan, inf, inf, 2.0, 2.0, nan, nan]], dtype=torch.float32)
    out = block_depth(d, 2)[0].numpy()
    assert out[0] == 3.0 and np.isposinf(out[1]) and np.isnan(out[2]) and np.isnan(out[3])


def test_levels_compute_a_coarse_level_once_and_drop_it_for_the_next():
    views = [View(0, torch.eye(3), torch.eye(4), torch.zeros(8, 8, 3), None, 8, 8, "front")]
    levels = Levels(views)
    quarter = levels.at(4)
    assert quarter[0].width == 2 and levels.at(4) is quarter
    assert levels.at(2)[0].width == 4 and levels.at(1) is views


class Killed(Exception):
    pass


RENDER_PARTS = rec.render_parts


def _recording(monkeypatch, stop_after=None):
    """Record (width, SH degree) of every training step; raise after ``stop_after`` steps (a killed run)."""
    seen = []

    def recorded(parts, view, degree, render_depth, cameras=None):
        if stop_after is not None and len(seen) == stop_after:
            raise Killed
        seen.append((view.width, degree))
        return RENDER_PARTS(parts, view, degree, render_depth, cameras)

    monkeypatch.setattr(rec, "render_parts", recorded)
    return seen


SCHEDULED = dict(iters=80, resolution_schedule=(0.25, 0.5), sh_degree=2, sh_every=25, densify_from=20,
                 densify_every=20, checkpoint_every=30, sky_points=0)


def _expected(cfg, start):
    return [(W // cfg.downscale_at(it), cfg.sh_degree_at(it)) for it in range(start, cfg.iters)]


def test_the_fit_trains_each_iteration_at_the_scheduled_resolution_and_degree(synthetic_package, tmp_path,
                                                                               monkeypatch):
    root, _ = synthetic_package
    cfg = ReconstructConfig(**SCHEDULED)
    seen = _recording(monkeypatch)
    result = rec.reconstruct(load_manifest(root), tmp_path, cfg, progress=False)
    assert seen == _expected(cfg, 0)
    assert {w for w, _ in seen} == {W // 4, W // 2, W} and {d for _, d in seen} == {0, 1, 2}
    assert result.metrics["downscale"] == [{"iteration": 0, "factor": 4}, {"iteration": 20, "factor": 2},
                                           {"iteration": 40, "factor": 1}]
    assert result.gaussians.sh_degree == 2


def test_a_resumed_fit_continues_the_schedule_where_it_stopped(synthetic_package, tmp_path, monkeypatch):
    root, _ = synthetic_package
    m = load_manifest(root)
    cfg = ReconstructConfig(**SCHEDULED)
    _recording(monkeypatch, stop_after=35)
    with pytest.raises(Killed):  # killed at iteration 35, after the checkpoint at 30
        rec.reconstruct(m, tmp_path, cfg, progress=False)
    seen = _recording(monkeypatch)
    result = rec.reconstruct(m, tmp_path, cfg, resume=True, progress=False)
    assert result.metrics["resumed_from"] == 30
    assert seen == _expected(cfg, 30) and seen[0] == (W // 2, 1)
    assert result.metrics["downscale"] == [{"iteration": 30, "factor": 2}, {"iteration": 40, "factor": 1}]


def test_the_default_schedule_follows_the_images_size(synthetic_package, tmp_path):
    root, _ = synthetic_package
    m = load_manifest(root)
    quick = dict(iters=40, densify_from=100, checkpoint_every=100, sky_points=0)
    small = rec.reconstruct(m, tmp_path / "small", ReconstructConfig(**quick), progress=False)
    assert small.metrics["downscale"] == [{"iteration": 0, "factor": 1}]  # 48x32: under the threshold
    large = rec.reconstruct(m, tmp_path / "large", ReconstructConfig(**quick, coarse_to_fine_pixels=W * H),
                            progress=False)
    assert large.metrics["downscale"] == [{"iteration": 0, "factor": 4}, {"iteration": 4, "factor": 2},
                                          {"iteration": 12, "factor": 1}]  # COARSE_TO_FINE of 40 iterations
