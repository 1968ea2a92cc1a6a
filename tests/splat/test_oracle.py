"""Forward agreement with the float64 brute-force oracle (independent code, no tiles)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from symdrive_core.splat import rasterize, render_oracle

from .scenes import args_of, random_scene

BG = (0.1, 0.5, 0.9)


@pytest.mark.parametrize("deg", [0, 3])
@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_numba_matches_oracle(deg, seed, dtype):
    s = random_scene(150, deg, seed, width=70, height=50)
    oracle = render_oracle(*args_of(s), background=torch.tensor(BG, dtype=torch.float64), render_depth=True)
    s = {k: (v.to(dtype) if torch.is_tensor(v) else v) for k, v in s.items()}
    rgb, alpha, info = rasterize(*args_of(s), background=torch.tensor(BG, dtype=dtype), render_depth=True,
                                 backend="numba")
    tol = 1e-4 if dtype == torch.float32 else 1e-10
    assert rgb.shape == (50, 70, 3) and alpha.shape == (50, 70, 1)
    assert info["n_visible"] > 50 and info["n_isect"] > 0
    assert alpha.max() > 0.5  # the scene is not empty
    np.testing.assert_allclose(rgb.numpy(), oracle["rgb"], atol=tol, rtol=0)
    np.testing.assert_allclose(alpha.numpy(), oracle["alpha"], atol=tol, rtol=0)
    np.testing.assert_allclose(info["depth"].numpy(), oracle["depth"], atol=tol * 100, rtol=0)
    np.testing.assert_array_equal(info["radii"].numpy(), oracle["radii"])


@pytest.mark.parametrize("kw", [dict(antialiased=True), dict(extent="3sigma"), dict(alpha_threshold=0.02),
                                dict(eps2d=0.0), dict(near=4.5, far=6.0), dict(extent=5.0)])
def test_options_match_oracle(kw):
    s = random_scene(150, 1, 7, width=61, height=45)
    oracle = render_oracle(*args_of(s), **kw)
    rgb, alpha, info = rasterize(*args_of(s), backend="numba", **kw)
    np.testing.assert_allclose(rgb.numpy(), oracle["rgb"], atol=1e-10, rtol=0)
    np.testing.assert_allclose(alpha.numpy(), oracle["alpha"], atol=1e-10, rtol=0)


def test_torch_reference_matches_oracle():
    s = random_scene(150, 3, 4, width=50, height=70)
    oracle = render_oracle(*args_of(s), render_depth=True)
    rgb, alpha, info = rasterize(*args_of(s), render_depth=True, backend="torch")
    np.testing.assert_allclose(rgb.numpy(), oracle["rgb"], atol=1e-10, rtol=0)
    np.testing.assert_allclose(alpha.numpy(), oracle["alpha"], atol=1e-10, rtol=0)


def test_opacity_extent_box_is_exact():
    """With the opacity-aware extent, the tile rule never changes a pixel (alpha < 1/255 outside)."""
    s = random_scene(200, 0, 3, width=64, height=48)
    a = render_oracle(*args_of(s), tile_cull=True)["rgb"]
    b = render_oracle(*args_of(s), tile_cull=False)["rgb"]
    np.testing.assert_allclose(a, b, atol=1e-12)


def test_dense_overlap_early_termination_matches_oracle():
    """Many large opaque Gaussians: most pixels stop early; the stop rule must match exactly."""
    s = random_scene(300, 0, 5, width=48, height=40, log_scale=-1.0)
    s["opacities"] = torch.full_like(s["opacities"], 0.95)
    oracle = render_oracle(*args_of(s))
    rgb, alpha, info = rasterize(*args_of(s), backend="numba")
    assert float(alpha.min()) > 0.9 and float((alpha > 0.999).float().mean()) > 0.5
    np.testing.assert_allclose(rgb.numpy(), oracle["rgb"], atol=1e-10)
