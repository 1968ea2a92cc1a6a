"""Degenerate and extreme inputs: outputs AND gradients stay finite (hypothesis-driven)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from symdrive_core.splat import rasterize

from ..splat.scenes import K_from_fov, look_at

SETTINGS = settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
W, H = 40, 30


def check(means, quats, scales, opac, colors, V=None, K=None, width=W, height=H, backend="numba", **kw):
    """Render, back-propagate a loss touching every output; assert everything is finite."""
    dtype = means.dtype
    V = torch.eye(4, dtype=dtype) if V is None else V
    K = K_from_fov(width, height, 60.0, dtype) if K is None else K
    ps = [t.detach().clone().requires_grad_(True) for t in (means, quats, scales, opac, colors)]
    rgb, alpha, info = rasterize(*ps, V, K, width, height, render_depth=True, backend=backend,
                                 background=torch.tensor([0.2, 0.4, 0.6], dtype=dtype), **kw)
    for name, t in (("rgb", rgb), ("alpha", alpha), ("depth", info["depth"])):
        assert torch.isfinite(t).all(), f"non-finite {name}"
    assert float(alpha.detach().min()) >= 0.0 and float(alpha.detach().max()) <= 1.0
    g = torch.Generator().manual_seed(0)
    loss = ((rgb * torch.rand(rgb.shape, generator=g, dtype=dtype)).sum() + alpha.sum()
            + (info["depth"] * alpha).sum())
    loss.backward()
    for name, p in zip(("means", "quats", "scales", "opacities", "colors"), ps):
        assert p.grad is not None and torch.isfinite(p.grad).all(), f"non-finite gradient for {name}"
    return rgb, alpha, info, ps


def scene(n, seed=0, z=4.0, dtype=torch.float32):
    g = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=g, dtype=dtype) * 0.5 + torch.tensor([0, 0, z], dtype=dtype)
    quats = torch.randn(n, 4, generator=g, dtype=dtype)
    scales = torch.exp(torch.randn(n, 3, generator=g, dtype=dtype) * 0.3 - 2.0)
    opac = torch.rand(n, generator=g, dtype=dtype)
    colors = torch.rand(n, 3, generator=g, dtype=dtype)
    return means, quats, scales, opac, colors


@SETTINGS
@given(st.lists(st.sampled_from([0.0, -0.0, 1e-30, 0.005, 0.01, 0.0100001, -0.01, -1.0, 1e-7, 0.02, 1e12, 1e10]),
                min_size=1, max_size=6), st.booleans())
def test_near_plane_and_z_zero(zs, antialiased):
    n = len(zs) + 20
    means, quats, scales, opac, colors = scene(n, len(zs))
    means[:len(zs), 2] = torch.tensor(zs)
    means[:len(zs), :2] *= 0.01
    check(means, quats, scales, opac, colors, antialiased=antialiased)


def test_gaussian_exactly_at_z_zero_gets_zero_gradient():
    means, quats, scales, opac, colors = scene(10)
    means[0] = torch.tensor([0.3, -0.2, 0.0])
    rgb, alpha, info, ps = check(means, quats, scales, opac, colors)
    assert int(info["radii"][0].abs().sum()) == 0
    assert float(ps[0].grad[0].abs().max()) == 0.0 and float(ps[0].grad[1:].abs().max()) > 0


@SETTINGS
@given(st.lists(st.tuples(st.floats(-8, 4), st.floats(-8, 4), st.floats(-8, 4)), min_size=1, max_size=5),
       st.booleans())
def test_scales_from_1e_minus8_to_1e4(log10_scales, antialiased):
    n = len(log10_scales)
    means, quats, scales, opac, colors = scene(n + 5, n)
    scales[:n] = torch.pow(10.0, torch.tensor(log10_scales))
    check(means, quats, scales, opac, colors, antialiased=antialiased)


@pytest.mark.parametrize("kind", ["flat", "needle", "zero", "zero_eps0"])
def test_degenerate_covariances(kind):
    means, quats, scales, opac, colors = scene(30, 1)
    if kind == "flat":
        scales[:, 2] = 0.0
    elif kind == "needle":
        scales[:, :2] = 1e-9
    else:
        scales[:] = 0.0
    check(means, quats, scales, opac, colors, eps2d=0.0 if kind == "zero_eps0" else 0.3)
    check(means, quats, scales, opac, colors, antialiased=True)


@SETTINGS
@given(st.lists(st.sampled_from([0.0, 1.0, 1e-9, 1.0 / 255.0, 0.5, 0.999999]), min_size=1, max_size=20))
def test_opacity_zero_and_one(values):
    n = len(values)
    means, quats, scales, opac, colors = scene(n, n)
    check(means, quats, scales, torch.tensor(values), colors)


def test_thousands_of_coincident_opaque_gaussians():
    n = 3000
    means = torch.tensor([[0.0, 0.0, 3.0]]).repeat(n, 1)
    quats = torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1)
    scales = torch.full((n, 3), 0.3)
    opac = torch.ones(n)
    colors = torch.rand(n, 3, generator=torch.Generator().manual_seed(0))
    rgb, alpha, info, ps = check(means, quats, scales, opac, colors)
    centre = alpha[H // 2, W // 2, 0]
    assert float(centre.detach()) > 0.999
    # the reference (cumulative products down to underflow) agrees and stays finite as well
    rgb_t, alpha_t, _, _ = check(means[:400], quats[:400], scales[:400], opac[:400], colors[:400], backend="torch")
    rgb_n, alpha_n, _, _ = check(means[:400], quats[:400], scales[:400], opac[:400], colors[:400])
    torch.testing.assert_close(rgb_t, rgb_n, atol=1e-5, rtol=0)


@SETTINGS
@given(st.lists(st.tuples(*[st.sampled_from([0.0, -0.0, 1e-20, 1e-3, -1.0, 2.0, 1e6, 1e20])] * 4),
                min_size=1, max_size=6))
def test_unnormalised_and_zero_quaternions(qs):
    n = len(qs)
    means, quats, scales, opac, colors = scene(n + 5, n)
    quats[:n] = torch.tensor(qs)
    check(means, quats, scales, opac, colors)


def test_zero_quaternion_is_identity():
    means, quats, scales, opac, colors = scene(5, 3)
    ident = torch.tensor([[1.0, 0, 0, 0]]).repeat(5, 1)
    a = check(means, ident, scales, opac, colors)[0]
    b = check(means, torch.zeros(5, 4), scales, opac, colors)[0]
    c = check(means, ident * 7.5, scales, opac, colors)[0]
    torch.testing.assert_close(a, b, atol=0, rtol=0)
    torch.testing.assert_close(a, c, atol=1e-6, rtol=0)


def test_non_finite_inputs_are_culled_not_propagated():
    means, quats, scales, opac, colors = scene(20, 4)
    means[0, 0] = float("nan")
    quats[1] = float("inf")
    scales[2, 1] = float("nan")
    opac[3] = float("nan")
    colors[4, 2] = float("inf")
    rgb, alpha, info, ps = check(means, quats, scales, opac, colors)
    assert not bool(info["visible"][:5].any())


@SETTINGS
@given(st.floats(10.0, 170.0), st.integers(1, 3))
def test_extreme_field_of_view(fov, seed):
    means, quats, scales, opac, colors = scene(60, seed)
    means[:, :2] *= 8.0  # spread sideways: many near the frustum edge for a narrow FOV
    check(means, quats, scales, opac, colors, K=K_from_fov(W, H, fov, torch.float32))


def test_camera_looking_straight_down():
    eye = np.array([5.0, -3.0, 20.0])
    V = torch.tensor(look_at(eye, eye - (0, 0, 10.0)), dtype=torch.float32)
    g = torch.Generator().manual_seed(0)
    means = torch.cat([torch.rand(200, 2, generator=g) * 20 - 10 + torch.tensor([5.0, -3.0]), torch.zeros(200, 1)], 1)
    quats, scales = torch.randn(200, 4, generator=g), torch.full((200, 3), 0.3)
    rgb, alpha, info, _ = check(means, quats, scales, torch.full((200,), 0.8), torch.rand(200, 3, generator=g), V=V)
    assert float(alpha.mean()) > 0.2
    hit = alpha[..., 0] > 0.01
    assert int(hit.sum()) > 100
    # every centre lies on the ground plane 20 m below the camera: expected depth is 20 everywhere
    torch.testing.assert_close(info["depth"][..., 0][hit], torch.full((int(hit.sum()),), 20.0), atol=1e-4, rtol=0)


@pytest.mark.parametrize("where", ["behind", "beyond_far", "off_image", "none"])
def test_empty_view_returns_background_exactly(where):
    means, quats, scales, opac, colors = scene(50, 5)
    if where == "behind":
        means[:, 2] = -means[:, 2]
    elif where == "beyond_far":
        means[:, 2] += 1e3
    elif where == "off_image":
        means[:, 0] += 1e3
    else:
        means, quats, scales, opac, colors = (t[:0] for t in (means, quats, scales, opac, colors))
    kw = {"far": 100.0} if where == "beyond_far" else {}
    rgb, alpha, info, ps = check(means, quats, scales, opac, colors, **kw)
    assert info["n_visible"] == 0 and info["n_isect"] == 0
    assert torch.equal(rgb, torch.tensor([0.2, 0.4, 0.6]).expand(H, W, 3))
    assert torch.equal(alpha, torch.zeros(H, W, 1))
    for p in ps:
        assert float(p.grad.abs().sum()) == 0.0


@pytest.mark.parametrize("width,height", [(1, 1), (1, 70), (17, 1), (33, 17), (16, 16)])
def test_odd_image_sizes_and_edges(width, height):
    means, quats, scales, opac, colors = scene(80, 6)
    check(means, quats, scales, opac, colors, K=K_from_fov(width, height, 60.0, torch.float32), width=width,
          height=height)


def test_huge_screen_footprints_do_not_overflow():
    """Radii far beyond int32 (scale 1e4 at the near plane) are clamped; boxes cover the image."""
    means = torch.tensor([[0.0, 0.0, 0.011], [0.0, 0.0, 0.5], [1e4, 1e4, 0.02], [0.0, 0.0, 1e9]])
    scales = torch.tensor([[1e4, 1e4, 1e4], [1e3, 1.0, 1e-3], [1e4, 1e4, 1.0], [1e6, 1e6, 1e6]])
    quats = torch.tensor([[1.0, 0, 0, 0]]).repeat(4, 1)
    rgb, alpha, info, _ = check(means, quats, scales, torch.full((4,), 0.9), torch.rand(4, 3))
    assert int(info["radii"].max()) <= 2 ** 30 and int(info["radii"].min()) >= 0
    tiles = math.ceil(W / 16) * math.ceil(H / 16)
    assert info["n_isect"] <= 4 * tiles


def test_far_from_origin_matches_origin():
    """Scene and camera 1e5 m from the origin vs the same at the origin (float32 Gaussians)."""
    means, quats, scales, opac, colors = scene(150, 7)
    means = torch.round(means * 64) / 64  # exact in float32 at 1e5 too
    off = torch.tensor([1e5, 1e5, -1e5])
    far_means = (means.double() + off.double()).float()
    assert torch.equal(far_means.double() - off.double(), means.double())
    V0 = torch.tensor(look_at((0.1, -0.2, 0.0), (0.0, 0.0, 4.0), up=(0, -1, 0)))
    V1 = torch.tensor(look_at(off.double().numpy() + (0.1, -0.2, 0.0), off.double().numpy() + (0.0, 0.0, 4.0),
                              up=(0, -1, 0)))
    K = K_from_fov(W, H, 60.0, torch.float32)
    a = check(means, quats, scales, opac, colors, V=V0.float(), K=K)
    b = check(far_means, quats, scales, opac, colors, V=V1, K=K)
    assert float(a[1].max()) > 0.5
    torch.testing.assert_close(a[0], b[0], atol=1e-4, rtol=0)
    torch.testing.assert_close(a[3][0].grad, b[3][0].grad, atol=1e-3 * float(a[3][0].grad.abs().max()), rtol=0)


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
def test_half_precision_inputs_render_as_float32_and_come_back_in_their_type(dtype):
    """The kernels have float32 and float64 paths; half-precision tensors (as a mixed-precision
    caller holds them) are rendered in float32, with gradients, instead of failing."""
    ref = scene(40)
    rgb32, alpha32, _, _ = check(*ref)
    rgb, alpha, _, ps = check(*(t.to(dtype) for t in ref), V=torch.eye(4, dtype=dtype),
                              K=K_from_fov(W, H, 60.0, torch.float32).to(dtype))
    assert rgb.dtype == dtype and alpha.dtype == dtype and all(p.grad.dtype == dtype for p in ps)
    tol = 2e-2 if dtype == torch.bfloat16 else 5e-3
    assert float((rgb.detach().float() - rgb32.detach()).abs().mean()) < tol
