"""Backward pass: numba kernels vs finite differences and vs autograd through the torch reference."""

from __future__ import annotations

import pytest
import torch

from symdrive_core.splat import rasterize

from .scenes import random_scene

NAMES = ("means", "quats", "scales", "opacities", "colors")


def _loss_fn(s, backend, weights, **kw):
    def loss(means, quats, scales, opacities, colors):
        rgb, alpha, info = rasterize(means, quats, scales, opacities, colors, s["viewmat"], s["K"], s["width"],
                                     s["height"], backend=backend, render_depth=True, **kw)
        # depth * alpha (the accumulated z) is smooth; the normalised depth jumps where alpha leaves 0
        out = (rgb * weights[0]).sum() + (alpha * weights[1]).sum() + (info["depth"] * alpha * weights[2]).sum()
        if "instance" in info:
            out = out + (info["instance"] * weights[3][..., : info["instance"].shape[-1]]).sum()
        return out
    return loss


def _weights(s, seed=11):
    g = torch.Generator().manual_seed(seed)
    H, W = s["height"], s["width"]
    return [torch.randn(H, W, 3, generator=g, dtype=torch.float64), torch.randn(H, W, 1, generator=g,
            dtype=torch.float64), 0.01 * torch.randn(H, W, 1, generator=g, dtype=torch.float64),
            torch.randn(H, W, 4, generator=g, dtype=torch.float64)]


def _grads(loss, params):
    ps = [p.detach().clone().requires_grad_(True) for p in params]
    loss(*ps).backward()
    return [p.grad for p in ps]


def _finite_differences(loss, params, eps=1e-6, per_tensor=40, seed=0):
    """Central differences at up to ``per_tensor`` random entries per tensor (NaN elsewhere)."""
    out = []
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for i, p in enumerate(params):
            g = torch.full_like(p, float("nan"))
            flat = g.view(-1)
            for j in torch.randperm(p.numel(), generator=gen)[:per_tensor].tolist():
                args = [q.clone() for q in params]
                args[i].view(-1)[j] += eps
                up = float(loss(*args))
                args[i].view(-1)[j] -= 2 * eps
                down = float(loss(*args))
                flat[j] = (up - down) / (2 * eps)
            out.append(g)
    return out


def _assert_close(name, got, want, rel=1e-3):
    picked = ~torch.isnan(want)
    got, want = got[picked], want[picked]
    scale = float(want.abs().max())
    assert scale > 0, f"{name}: zero gradient, the check would prove nothing"
    err = float((got - want).abs().max())
    assert err <= rel * scale, f"{name}: max error {err:.3e} vs max |grad| {scale:.3e}"
    assert float((got - want).norm()) <= rel * float(want.norm()), name


@pytest.mark.parametrize("deg", [None, 3])
def test_numba_backward_matches_finite_differences(deg):
    """Smooth setting (tiny alpha threshold, wide box): the rasterizer is differentiable everywhere."""
    s = random_scene(10, deg, seed=3, width=40, height=30, depth=4.0, spread=0.5, log_scale=-1.8)
    s["opacities"] = 0.2 + 0.6 * s["opacities"]
    kw = dict(alpha_threshold=1e-10, extent=8.0, antialiased=True)
    loss = _loss_fn(s, "numba", _weights(s), **kw)
    params = [s[k] for k in NAMES]
    got = _grads(loss, params)
    want = _finite_differences(loss, params)
    for name, a, b in zip(NAMES, got, want):
        _assert_close(name, a, b)


@pytest.mark.parametrize("seed,deg,aa", [(0, 0, False), (1, 3, True), (2, None, False), (3, 3, False)])
def test_numba_backward_matches_autograd_reference(seed, deg, aa):
    """Default thresholds and stop rule; same discrete decisions, so the gradients agree to rounding."""
    s = random_scene(150, deg, seed, width=70, height=50)
    w = _weights(s, seed)
    n = s["means"].shape[0]
    groups = torch.randint(-1, 4, (n,), generator=torch.Generator().manual_seed(seed))
    kw = dict(antialiased=aa, background=torch.tensor([0.3, 0.2, 0.1], dtype=torch.float64), groups=groups,
              n_groups=4)
    params = [s[k] for k in NAMES]
    got = _grads(_loss_fn(s, "numba", w, **kw), params)
    want = _grads(_loss_fn(s, "torch", w, **kw), params)
    for name, a, b in zip(NAMES, got, want):
        _assert_close(name, a, b, rel=1e-9)


def test_float32_backward_close_to_float64():
    s = random_scene(150, 3, 5, width=64, height=48)
    w = _weights(s)
    params = [s[k] for k in NAMES]
    g64 = _grads(_loss_fn(s, "numba", w), params)
    s32 = {k: (v.float() if torch.is_tensor(v) else v) for k, v in s.items()}
    w32 = [x.float() for x in w]
    g32 = _grads(_loss_fn(s32, "numba", w32), [s32[k] for k in NAMES])
    for name, a, b in zip(NAMES, g32, g64):
        _assert_close(name, a.double(), b, rel=2e-3)


def test_instance_gradient_reaches_colours_only_through_rgb():
    """Instance masks depend on opacity/geometry, not colour; rgb depends on colour."""
    s = random_scene(60, None, 2, width=40, height=30)
    n = s["means"].shape[0]
    op = s["opacities"].clone().requires_grad_(True)
    col = s["colors"].clone().requires_grad_(True)
    rgb, alpha, info = rasterize(s["means"], s["quats"], s["scales"], op, col, s["viewmat"], s["K"], 40, 30,
                                 groups=torch.zeros(n, dtype=torch.int64), n_groups=1)
    torch.testing.assert_close(info["instance"], alpha)  # one group holding everything == alpha
    info["instance"].sum().backward()
    assert col.grad is None or float(col.grad.abs().max()) == 0.0
    assert float(op.grad.abs().max()) > 0
