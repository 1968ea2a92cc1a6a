"""The frame path that reads visible rows in place against the path it replaced.

``rasterize`` (indexed SH colour, one-pass gathers with full-size gradients, depth-ordered binning,
parallel gradient reduction) must give the colours, alpha and gradients of
:func:`rasterize_baseline` (torch gathers and index-put backward) on hard cases: Gaussians behind the
camera, zero scales, every SH degree, float32 and float64.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from symdrive_core.bench.rasterize_baseline import rasterize_baseline
from symdrive_core.splat import rasterize
from symdrive_core.splat.sh import sh_to_color


def street(n, width, height, deg, dtype, seed=0):
    """A random cloud in front of the camera, some of it behind, some with zero scales."""
    g = torch.Generator().manual_seed(seed)
    z = 2 + 20 * torch.rand(n, generator=g, dtype=torch.float64)
    z[: n // 10] *= -1.0  # behind the camera
    x = (torch.rand(n, generator=g, dtype=torch.float64) * 2 - 1) * z.abs() * 0.8
    y = (torch.rand(n, generator=g, dtype=torch.float64) * 2 - 1) * z.abs() * 0.5
    means = torch.stack([x, y, z], 1)
    quats = torch.randn(n, 4, generator=g, dtype=torch.float64)
    scales = torch.exp(torch.randn(n, 3, generator=g, dtype=torch.float64) * 0.5) * 0.05 * z.abs()[:, None]
    scales[n // 10: n // 10 + 5] = 0.0
    opac = torch.sigmoid(torch.randn(n, generator=g, dtype=torch.float64) + 1.0)
    sh = torch.randn(n, (deg + 1) ** 2, 3, generator=g, dtype=torch.float64) * 0.3
    f = 0.5 * width / math.tan(math.radians(35))
    K = torch.tensor([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1.0]], dtype=dtype)
    return [t.to(dtype) for t in (means, quats, scales, opac, sh)], torch.eye(4, dtype=dtype), K


@pytest.mark.parametrize("deg", [0, 1, 2, 3])
@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_frame_matches_the_baseline_path(deg, dtype):
    W, H = 96, 64
    ps, V, K = street(600, W, H, deg, dtype, seed=deg)
    results = []
    for fn in (rasterize, rasterize_baseline):
        leaf = [p.detach().requires_grad_(True) for p in ps]
        rgb, alpha = fn(*leaf, V, K, W, H)[:2]
        weights = torch.linspace(0.2, 1.0, W * H * 3, dtype=dtype).reshape(H, W, 3)
        ((rgb * weights).sum() + alpha.sum()).backward()
        results.append([rgb.detach(), alpha.detach()] + [p.grad for p in leaf])
    tol = 1e-10 if dtype == torch.float64 else 2e-5
    for got, want in zip(*results):
        scale = max(1.0, float(want.abs().max()))
        torch.testing.assert_close(got, want, atol=tol * scale, rtol=0)
    assert float(results[1][1].max()) > 0.5  # the scene covers the image


@pytest.mark.parametrize("deg", [0, 1, 2, 3])
@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_sh_colour_of_picked_rows_is_that_of_the_gathered_rows(deg, dtype):
    rng = np.random.default_rng(deg)
    n = 300
    sh = torch.tensor(rng.normal(size=(n, 16, 3)) * 0.4, dtype=dtype)
    dirs = torch.tensor(rng.normal(size=(n, 3)), dtype=torch.float64)
    dirs[:7] = 0.0  # zero directions: zero vector, finite gradient
    rows = np.sort(rng.choice(n, 180, replace=False)).astype(np.int64)
    picked = [sh.clone().requires_grad_(True), dirs.clone().requires_grad_(True)]
    gathered = [sh.clone().requires_grad_(True), dirs.clone().requires_grad_(True)]
    out = sh_to_color(deg, *picked, rows=rows)
    idx = torch.from_numpy(rows)
    want = sh_to_color(deg, gathered[0][idx], gathered[1][idx])
    torch.testing.assert_close(out, want, atol=0, rtol=0)
    g = torch.tensor(rng.normal(size=out.shape), dtype=dtype)
    (out * g).sum().backward()
    (want * g).sum().backward()
    for a, b in zip(picked, gathered):
        torch.testing.assert_close(a.grad, b.grad, atol=0, rtol=0)
        assert bool(torch.isfinite(a.grad).all())
