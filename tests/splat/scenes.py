"""Random test scenes for the rasterizer tests (made in the test, nothing downloaded)."""

from __future__ import annotations

import math

import numpy as np
import torch


def random_scene(n=120, deg=0, seed=0, width=70, height=50, dtype=torch.float64, depth=5.0, spread=1.0,
                 log_scale=-2.5, fx=60.0, fy=55.0, cx_shift=7.0, cy_shift=-4.0):
    """Gaussians in front of a camera at the origin (OpenCV), off-centre principal point."""
    g = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=g, dtype=dtype) * spread + torch.tensor([0.0, 0.0, depth], dtype=dtype)
    quats = torch.randn(n, 4, generator=g, dtype=dtype)
    scales = torch.exp(torch.randn(n, 3, generator=g, dtype=dtype) * 0.5 + log_scale)
    opac = torch.sigmoid(torch.randn(n, generator=g, dtype=dtype))
    colors = torch.randn(n, (deg + 1) ** 2, 3, generator=g, dtype=dtype) * 0.5 if deg is not None else \
        torch.rand(n, 3, generator=g, dtype=dtype)
    K = torch.tensor([[fx, 0.0, width / 2 + cx_shift], [0.0, fy, height / 2 + cy_shift], [0.0, 0.0, 1.0]],
                     dtype=dtype)
    return dict(means=means, quats=quats, scales=scales, opacities=opac, colors=colors,
                viewmat=torch.eye(4, dtype=dtype), K=K, width=width, height=height)


def args_of(s):
    return (s["means"], s["quats"], s["scales"], s["opacities"], s["colors"], s["viewmat"], s["K"], s["width"],
            s["height"])


def look_at(eye, target, up=(0.0, 0.0, 1.0)):
    """world->camera 4x4 (OpenCV) looking from eye to target, float64 numpy."""
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = x, y, z, eye
    R = c2w[:3, :3]
    w2c = np.eye(4)
    w2c[:3, :3] = R.T
    w2c[:3, 3] = -R.T @ eye
    return w2c


def K_from_fov(width, height, fov_deg, dtype=torch.float64):
    f = 0.5 * width / math.tan(math.radians(fov_deg) / 2)
    return torch.tensor([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1.0]], dtype=dtype)
