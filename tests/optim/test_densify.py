import numpy as np
import torch

from symdrive_core.optim.densify import (
    DensifyConfig,
    GradStats,
    append,
    densify_and_prune,
    ndc_gradient_norm,
    prune,
)


def _params(n=4):
    g = torch.Generator().manual_seed(0)
    p = {"means": torch.randn(n, 3, generator=g), "quats": torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
         "log_scales": torch.full((n, 3), -3.0), "opacity_logits": torch.zeros(n), "sh0": torch.rand(n, 1, 3, generator=g)}
    params = {k: torch.nn.Parameter(v) for k, v in p.items()}
    opt = torch.optim.Adam([{"params": [v], "lr": 0.01, "name": k} for k, v in params.items()])
    loss = sum((v * torch.arange(1, n + 1).reshape(-1, *[1] * (v.dim() - 1))).sum() for v in params.values())
    loss.backward()
    opt.step()
    return params, opt


def _moments(opt, name):
    group = next(g for g in opt.param_groups if g["name"] == name)
    return group["params"][0], opt.state[group["params"][0]]["exp_avg"]


def test_prune_and_append_keep_adam_moments_aligned():
    params, opt = _params()
    _, before = _moments(opt, "means")
    before = before.clone()
    prune(opt, params, torch.tensor([True, False, True, True]))
    p, m = _moments(opt, "means")
    assert p is params["means"] and torch.equal(m, before[[0, 2, 3]])
    append(opt, params, {k: v.detach()[:2].clone() for k, v in params.items()})
    p, m = _moments(opt, "means")
    assert p.shape[0] == 5 and torch.equal(m[:3], before[[0, 2, 3]]) and not m[3:].any()
    assert all(g["params"][0].shape[0] == 5 for g in opt.param_groups)


def test_hot_small_gaussians_clone_hot_large_ones_split_and_faint_ones_go():
    params, opt = _params(4)
    with torch.no_grad():
        params["log_scales"][1] = np.log(2.0)  # large
        params["opacity_logits"][3] = -10.0  # nearly transparent
    stats = GradStats(4)
    stats.add(torch.tensor([1.0, 1.0, 0.0, 0.0]), torch.ones(4, dtype=torch.bool))
    parent = params["means"][1].detach().clone()
    out = densify_and_prune(opt, params, stats, DensifyConfig(grad_threshold=0.5), extent=10.0,
                            centre=torch.zeros(3), generator=torch.Generator().manual_seed(0))
    assert out == {"cloned": 1, "split": 1, "pruned": 1}
    # 4 + 1 clone + 2 children - 1 split parent - 1 faint = 5
    assert params["means"].shape[0] == 5 and stats.count.shape[0] == 5
    children = params["log_scales"][-2:].exp()
    assert torch.allclose(children, torch.full_like(children, 2.0 / 1.6))
    assert (params["means"][-2:] - parent).norm(dim=1).max() < 10.0


def test_ndc_gradient_scales_pixels_to_half_the_image():
    g = torch.tensor([[1.0, 0.0], [0.0, 2.0]])
    assert torch.allclose(ndc_gradient_norm(g, 100, 50), torch.tensor([50.0, 50.0]))
