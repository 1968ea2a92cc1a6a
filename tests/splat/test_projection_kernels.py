"""The numba projection and SH kernels (hand-written backward) against the torch versions (autograd)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from symdrive_core.splat import proj_kernels
from symdrive_core.splat.projection import project_gaussians, project_gaussians_torch
from symdrive_core.splat.sh import eval_sh, eval_sh_torch, sh_to_color, sh_to_color_torch

from .scenes import K_from_fov, look_at

OUTPUTS = ("means2d", "conics", "depths", "opacities", "rel_means")


def _scene(n=400, seed=0, offset=(0.0, 0.0, 0.0), dtype=torch.float64):
    """Gaussians around a tilted camera, with every culling case mixed in."""
    g = torch.Generator().manual_seed(seed)
    off = torch.tensor(offset, dtype=torch.float64)
    eye = torch.tensor([1.0, -2.0, 1.5], dtype=torch.float64) + off
    view = torch.as_tensor(look_at(eye.numpy(), (eye + torch.tensor([3.0, 8.0, -0.5], dtype=torch.float64)).numpy()))
    W, H = 64, 40
    K = K_from_fov(W, H, 80.0)
    K[0, 2] += 5.0
    K[1, 2] -= 3.0
    cam_rot = view[:3, :3].T  # camera -> world rotation
    pc = torch.randn(n, 3, generator=g, dtype=torch.float64) * torch.tensor([3.0, 2.0, 3.0])
    pc[:, 2] += 5.0  # mostly in front, some behind
    pc[0] = torch.tensor([0.3, -0.2, 0.0])  # z = 0 exactly
    pc[1] = torch.tensor([0.1, 0.1, 0.01])  # on the near plane
    pc[2] = torch.tensor([0.0, 0.0, -1.0])  # behind
    pc[3] = torch.tensor([40.0, 0.0, 2.0])  # far outside the widened frustum (clamped Jacobian)
    pc[4] = torch.tensor([0.0, 0.0, 1e11])  # beyond far
    means = (pc @ cam_rot.T + eye).to(dtype)
    quats = torch.randn(n, 4, generator=g, dtype=torch.float64).to(dtype)
    quats[5] = 0.0  # zero quaternion -> identity
    scales = torch.exp(torch.randn(n, 3, generator=g, dtype=torch.float64) * 0.7 - 2.0).to(dtype)
    scales[6] = torch.tensor([1e-8, 1e-8, 1e-8], dtype=dtype)  # below eps2d: flat
    opac = torch.sigmoid(torch.randn(n, generator=g, dtype=torch.float64)).to(dtype)
    opac[7] = 1e-4  # under the alpha threshold
    opac[8] = 1.0
    means[9, 1] = float("nan")  # non-finite: culled
    finite = torch.ones(n, dtype=torch.bool)
    finite[10] = False  # e.g. a non-finite colour
    return means, quats, scales, opac, view.to(dtype), K.to(dtype), W, H, finite


def _weights(proj, seed):
    g = torch.Generator().manual_seed(seed)
    return {k: torch.randn(getattr(proj, k).shape, generator=g, dtype=torch.float64) for k in OUTPUTS}


def _loss(proj, w):
    return sum((getattr(proj, k).to(torch.float64) * w[k]).sum() for k in OUTPUTS)


@pytest.mark.parametrize("antialiased", [False, True])
@pytest.mark.parametrize("extent", ["opacity", "3sigma", 2.5])
@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (1e5, -1e5, 30.0)])
def test_numba_projection_matches_torch(antialiased, extent, offset):
    means, quats, scales, opac, view, K, W, H, finite = _scene(offset=offset)
    kw = dict(antialiased=antialiased, extent=extent, finite_mask=finite, eps2d=0.3, near=0.01, far=1e10)
    leaves = [t.clone().requires_grad_(True) for t in (means, quats, scales, opac)]
    ref = project_gaussians_torch(*leaves, view, K, W, H, **kw)
    leaves2 = [t.clone().requires_grad_(True) for t in (means, quats, scales, opac)]
    got = project_gaussians(*leaves2, view, K, W, H, backend="numba", **kw)
    assert torch.equal(got.visible, ref.visible) and torch.equal(got.radii, ref.radii)
    assert int(got.visible.sum()) > 100 and not bool(got.visible[[0, 2, 3, 4, 7, 9, 10]].any())
    for k in OUTPUTS:
        torch.testing.assert_close(getattr(got, k), getattr(ref, k), rtol=1e-12, atol=1e-12, msg=k)
    w = _weights(ref, 1)
    w["rel_means"][:11] = 0.0  # rel_means = means - camera carries a gradient even when culled
    g_ref = torch.autograd.grad(_loss(ref, w), leaves)
    g_got = torch.autograd.grad(_loss(got, w), leaves2)
    for name, a, b in zip(("means", "quats", "scales", "opacities"), g_got, g_ref):
        assert torch.isfinite(a).all(), name
        scale = float(b.abs().max())
        assert scale > 0, name
        torch.testing.assert_close(a, b, rtol=1e-9, atol=1e-10 * scale, msg=name)
    assert float(g_got[0][0].abs().max()) == 0.0  # z = 0: exactly zero
    assert float(g_got[0][9].abs().max()) == 0.0 and float(g_got[0][10].abs().max()) == 0.0


def test_numba_projection_float32_close_to_torch():
    means, quats, scales, opac, view, K, W, H, finite = _scene(dtype=torch.float32)
    leaves = [t.clone().requires_grad_(True) for t in (means, quats, scales, opac)]
    ref = project_gaussians_torch(*leaves, view, K, W, H, antialiased=True)
    leaves2 = [t.clone().requires_grad_(True) for t in (means, quats, scales, opac)]
    got = project_gaussians(*leaves2, view, K, W, H, antialiased=True)
    assert got.means2d.dtype == torch.float32 and got.rel_means.dtype == torch.float64
    assert torch.equal(got.visible, ref.visible)
    for k in OUTPUTS:
        torch.testing.assert_close(getattr(got, k), getattr(ref, k), rtol=1e-5, atol=1e-5, msg=k)
    w = _weights(ref, 2)
    for a, b in zip(torch.autograd.grad(_loss(got, w), leaves2), torch.autograd.grad(_loss(ref, w), leaves)):
        assert a.dtype == b.dtype
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-4 * float(b.abs().max()))


def test_projection_backend_choice_and_errors():
    means, quats, scales, opac, view, K, W, H, _ = _scene(n=20)
    with pytest.raises(ValueError):
        project_gaussians(means, quats, scales, opac, view, K, W, H, extent="5sigma")
    with pytest.raises(ValueError):
        project_gaussians(means, quats, scales, opac, view, K, W, H, backend="opengl")
    empty = project_gaussians(means[:0], quats[:0], scales[:0], opac[:0], view, K, W, H)
    assert empty.means2d.shape == (0, 2) and empty.radii.shape == (0, 2)


@pytest.mark.parametrize("deg", [0, 1, 2, 3])
@pytest.mark.parametrize("clamped", [False, True])
def test_numba_sh_matches_torch(deg, clamped):
    g = torch.Generator().manual_seed(10 + deg)
    n = 300
    sh = torch.randn(n, 16, 3, generator=g, dtype=torch.float64) * 0.6  # more coefficients than the degree uses
    dirs = torch.randn(n, 3, generator=g, dtype=torch.float64) * 5
    dirs[0] = 0.0  # zero direction
    dirs[1] = torch.tensor([1e5, -2e5, 3e4], dtype=torch.float64)
    dirs[2, 0] = float("inf")
    fast, ref = (sh_to_color, sh_to_color_torch) if clamped else (eval_sh, eval_sh_torch)
    a_sh, a_d = sh.clone().requires_grad_(True), dirs.clone().requires_grad_(True)
    b_sh, b_d = sh.clone().requires_grad_(True), dirs.clone().requires_grad_(True)
    got = fast(deg, a_sh, a_d, backend="numba")
    want = ref(deg, b_sh, b_d)
    torch.testing.assert_close(got, want, rtol=1e-13, atol=1e-13)
    if clamped:
        assert bool((want == 0).any()) and bool((want > 0).any())  # both sides of the clamp exercised
    w = torch.randn(n, 3, generator=g, dtype=torch.float64)
    ga = torch.autograd.grad((got * w).sum(), (a_sh, a_d))
    gb = torch.autograd.grad((want * w).sum(), (b_sh, b_d), allow_unused=True)
    gb = [torch.zeros_like(x) if y is None else y for x, y in zip(ga, gb)]  # degree 0 ignores the direction
    for name, x, y in zip(("sh", "dirs"), ga, gb):
        assert torch.isfinite(x).all(), name
        torch.testing.assert_close(x, y, rtol=1e-11, atol=1e-12, msg=name)
    if deg > 0:
        assert float(ga[1][3:].abs().max()) > 0


def test_numba_sh_float32_and_errors():
    g = torch.Generator().manual_seed(3)
    sh = torch.randn(50, 16, 3, generator=g)
    dirs = torch.randn(50, 3, generator=g, dtype=torch.float64)
    got = sh_to_color(3, sh, dirs)
    assert got.dtype == torch.float32
    torch.testing.assert_close(got, sh_to_color_torch(3, sh, dirs), rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError):
        sh_to_color(3, sh[:, :9], dirs)
    with pytest.raises(ValueError):
        eval_sh(4, sh, dirs)
    assert math.isfinite(float(eval_sh(0, sh[:0], dirs[:0]).sum()))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_rows_finite_flags_every_non_finite_entry(dtype):
    rng = np.random.default_rng(4)
    a = rng.normal(size=(300, 48)).astype(dtype)
    a[:, 0] = np.finfo(dtype).max  # huge, tiny and signed zeros are finite
    a[:, 1] = -np.finfo(dtype).tiny / 4
    a[:, 2] = -0.0
    bad = rng.choice(300, 40, replace=False)
    a[bad, rng.integers(0, 48, 40)] = rng.choice([np.inf, -np.inf, np.nan], 40)
    out = np.empty(300, np.bool_)
    proj_kernels.rows_finite(a, out)
    np.testing.assert_array_equal(out, np.isfinite(a).all(1))
    assert (~out).sum() == 40
