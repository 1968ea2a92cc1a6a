"""Scene composition: background plus rigidly moving actors in ONE rasterizer call.

Each actor layer is moved by its pose (vehicle-local -> world): ``mu_w = R mu_l + T``,
``q_w = q_R (x) q_l``; its SH is evaluated with the view direction in the actor's LOCAL frame,
``d_l = R^T (mu_w - c) = mu_l + R^T (T - c)`` (exact; no SH rotation needed). Positions are formed
relative to the camera centre in float64, so large world coordinates keep their precision. An actor
whose padded local box falls outside the view frustum is culled before projection. The instance
output is, per actor, the accumulated ``alpha_i T_i`` of its Gaussians (computed in the same pass
by the kernels' group channel; differentiable w.r.t. the actor's opacities and geometry).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..scene.visibility import box_corners_world, box_in_frustum
from .constants import ALPHA_THRESHOLD
from .projection import camera_center
from .rasterize import rasterize
from .sh import sh_to_color
from .tensors import GaussianTensors


@dataclass
class Layer:
    gaussians: GaussianTensors
    rotation: torch.Tensor | None = None  # [3, 3] local -> world; None = identity
    translation: torch.Tensor | None = None  # [3]; None = zero
    actor_id: int = 0  # 0 = background (no instance channel)


def rotmat_to_quat(R: torch.Tensor) -> torch.Tensor:
    """Rotation matrix [3,3] -> unit quaternion wxyz (numerically robust branch choice)."""
    m = R.detach().to(torch.float64).cpu().numpy()
    tr = np.trace(m)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    q = np.asarray(q)
    return torch.as_tensor(q / np.linalg.norm(q))


def quat_multiply(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product a (x) b of wxyz quaternions (broadcasting)."""
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack([aw * bw - ax * bx - ay * by - az * bz,
                        aw * bx + ax * bw + ay * bz - az * by,
                        aw * by - ax * bz + ay * bw + az * bx,
                        aw * bz + ax * by - ay * bx + az * bw], -1)


def render_layers(layers: list[Layer], viewmat: torch.Tensor, K: torch.Tensor, width: int, height: int, *,
                  background=None, near: float = 0.01, far: float = 1e10, eps2d: float = 0.3,
                  antialiased: bool = False, alpha_threshold: float = ALPHA_THRESHOLD, extent="opacity",
                  backend: str = "auto", cull: bool = True) -> dict:
    """Render layers together. Returns dict(rgb [H,W,3], alpha [H,W,1], depth [H,W,1],
    instance [H,W,n_actors], actor_ids [ids of the instance channels, in first-seen order, background
    excluded], culled [actor ids culled by the frustum test], info)."""
    device = viewmat.device
    dtype = None
    c = camera_center(viewmat)  # float64
    Kn = K.detach().double().cpu().numpy()
    # camera-centred world: same rotation, zero translation
    view0 = torch.eye(4, dtype=torch.float64)
    view0[:3, :3] = viewmat.detach().double()[:3, :3]
    actor_ids: list[int] = []
    culled: list[int] = []
    parts = {k: [] for k in ("means", "quats", "scales", "opac", "colors", "groups")}
    for layer in layers:
        g = layer.gaussians
        dtype = dtype or g.means.dtype
        aid = int(layer.actor_id)
        if aid != 0 and aid not in actor_ids:
            actor_ids.append(aid)
        if len(g) == 0:
            continue
        R = None if layer.rotation is None else layer.rotation.detach().to(torch.float64).cpu()
        T = (torch.zeros(3, dtype=torch.float64) if layer.translation is None
             else layer.translation.detach().to(torch.float64).cpu())
        if cull and aid != 0:
            lo, hi = g.local_bounds()
            corners = box_corners_world(lo.numpy(), hi.numpy(), np.eye(3) if R is None else R.numpy(),
                                        T.numpy())
            if not box_in_frustum(corners, viewmat.detach().double().cpu().numpy(), Kn, width, height, near, far):
                culled.append(aid)
                continue
        offset = (T - c).to(device)  # float64: translation relative to the camera centre
        m_local = g.means.to(torch.float64)
        if R is None:
            m_rel = m_local + offset
            q = g.quats
            dirs = m_rel
        else:
            Rd = R.to(device)
            m_rel = m_local @ Rd.T + offset
            q = quat_multiply(rotmat_to_quat(R).to(device=device, dtype=g.quats.dtype), g.quats)
            dirs = m_local + Rd.T @ offset  # d_l = R^T (mu_w - c)
        parts["means"].append(m_rel)
        parts["quats"].append(q)
        parts["scales"].append(g.scales)
        parts["opac"].append(g.opacities)
        sh_backend = "torch" if backend == "torch" else "auto"
        parts["colors"].append(sh_to_color(g.sh_degree, g.sh, dirs, backend=sh_backend).to(g.sh.dtype))
        k = actor_ids.index(aid) if aid != 0 else -1
        parts["groups"].append(torch.full((len(g),), k, dtype=torch.int64, device=device))
    dtype = dtype or torch.float32
    G = len(actor_ids)
    if parts["means"]:
        cat = {k: torch.cat(v, 0) for k, v in parts.items()}
    else:
        z = lambda *s: torch.zeros(*s, dtype=dtype, device=device)
        cat = {"means": z(0, 3).double(), "quats": z(0, 4), "scales": z(0, 3), "opac": z(0), "colors": z(0, 3),
               "groups": torch.zeros(0, dtype=torch.int64, device=device)}
    # means are camera-relative (formed in float64, small now); the rasterizer sees a camera at the origin
    rgb, alpha, info = rasterize(cat["means"].to(dtype), cat["quats"].to(dtype), cat["scales"].to(dtype),
                                 cat["opac"].to(dtype), cat["colors"].to(dtype), view0.to(device), K,
                                 width, height, background=background, near=near, far=far, eps2d=eps2d,
                                 antialiased=antialiased, render_depth=True, alpha_threshold=alpha_threshold,
                                 extent=extent, backend=backend, groups=cat["groups"], n_groups=G)
    inst = info.get("instance")
    if inst is None:
        inst = torch.zeros(height, width, G, dtype=rgb.dtype, device=rgb.device)
    return {"rgb": rgb, "alpha": alpha, "depth": info["depth"], "instance": inst, "actor_ids": actor_ids,
            "culled": culled, "info": info}
