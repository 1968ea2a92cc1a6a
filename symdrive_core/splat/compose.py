"""Scene composition: background plus rigidly moving actors as ONE set of rasterizer inputs.

Each actor layer is moved by its pose (vehicle-local -> world): ``mu_w = R mu_l + T``,
``q_w = q_R (x) q_l``; its SH is evaluated with the view direction in the actor's LOCAL frame,
``d_l = R^T (mu_w - c) = mu_l + R^T (T - c)`` (exact; no SH rotation needed). The pose stays in
the autograd graph (means, orientations, view directions), so a learnt pose correction gets the
image's gradient. Positions are formed relative to the camera centre in float64, so large world
coordinates keep their precision. An actor whose padded local box falls outside the view frustum is
culled before projection. Each actor's Gaussians carry its group index, so the rasterizer
accumulates the actor's ``alpha_i T_i`` as an instance channel in the same pass. :func:`symdrive_core.splat.render.render_layers` renders the result.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..conventions import FAR_PLANE, NEAR_PLANE
from ..rotations import matrix_to_quat
from ..scene.visibility import box_corners_world, box_in_frustum
from .projection import camera_center
from .sh import sh_to_color
from .tensors import GaussianTensors


@dataclass
class Layer:
    gaussians: GaussianTensors
    rotation: torch.Tensor | None = None  # [3, 3] local -> world; None = identity
    translation: torch.Tensor | None = None  # [3], float64 (world coordinates may be UTM); None = zero
    actor_id: int = 0  # 0 = background (no instance channel)


@dataclass
class Composed:
    """Every layer's Gaussians in one camera-centred world (same rotation as the camera, origin at its centre)."""

    means: torch.Tensor  # [N, 3] float64, relative to the camera centre
    quats: torch.Tensor  # [N, 4]
    scales: torch.Tensor  # [N, 3]
    opacities: torch.Tensor  # [N]
    colors: torch.Tensor  # [N, 3], SH evaluated for this camera
    groups: torch.Tensor  # [N] int64: index into actor_ids, -1 for the background
    viewmat: torch.Tensor  # [4, 4] float64: the camera's rotation, zero translation
    actor_ids: list[int]  # ids of the instance channels, in first-seen order, background excluded
    culled: list[int]  # actor ids culled by the frustum test
    dtype: torch.dtype  # the layers' storage dtype


def _left_product(q: torch.Tensor) -> torch.Tensor:
    """[4, 4] ``L`` with ``q (x) p = L @ p`` (Hamilton, wxyz): linear in ``q``."""
    w, x, y, z = q
    return torch.stack([torch.stack([w, -x, -y, -z]), torch.stack([x, w, -z, y]),
                        torch.stack([y, z, w, -x]), torch.stack([z, -y, x, w])])


def rotation_quat(R: torch.Tensor) -> torch.Tensor:
    """[4] wxyz quaternion of the rotation ``R`` [3, 3] (float64), in the graph of ``R``: a learnt
    pose's gradient reaches it through the Gaussians' orientations too. The value is
    ``matrix_to_quat`` of ``R`` (Shepperd, any rotation); the gradient comes from the quaternion of
    ``R0^T R`` (``R0`` = ``R`` detached), the identity in value, where the trace branch is exact."""
    R0 = R.detach()
    q0 = torch.as_tensor(matrix_to_quat(R0.cpu().numpy()), dtype=R.dtype, device=R.device)
    if not R.requires_grad:
        return q0
    D = R0.T @ R
    w = 0.5 * torch.sqrt(1.0 + torch.trace(D))
    dq = torch.stack([w, (D[2, 1] - D[1, 2]) / (4 * w), (D[0, 2] - D[2, 0]) / (4 * w), (D[1, 0] - D[0, 1]) / (4 * w)])
    return _left_product(q0) @ dq


def rotate_quats(R: torch.Tensor, quats: torch.Tensor) -> torch.Tensor:
    """``q_R (x) q`` for every row of ``quats``: one 4x4 matrix (linear in ``q``, so gradients reach
    it, and ``R``'s when it carries them)."""
    left = _left_product(rotation_quat(torch.as_tensor(R, dtype=torch.float64)))
    return quats @ left.T.to(dtype=quats.dtype, device=quats.device)


def compose_layers(layers: list[Layer], viewmat: torch.Tensor, K: torch.Tensor, width: int, height: int, *,
                   near: float = NEAR_PLANE, far: float = FAR_PLANE, cull: bool = True, sh_backend: str = "auto") -> Composed:
    """The layers placed, culled and coloured for the camera ``viewmat`` / ``K``."""
    device = viewmat.device
    dtype = None
    c = camera_center(viewmat)  # float64
    Kn = K.detach().double().cpu().numpy()
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
        # float64 and in the graph: a pose being learnt gets its gradient from the image
        R = None if layer.rotation is None else layer.rotation.to(torch.float64).cpu()
        T = (torch.zeros(3, dtype=torch.float64) if layer.translation is None
             else layer.translation.to(torch.float64).cpu())
        if cull and aid != 0:
            lo, hi = g.local_bounds()
            corners = box_corners_world(lo.numpy(), hi.numpy(), np.eye(3) if R is None else R.detach().numpy(),
                                        T.detach().numpy())
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
            q = rotate_quats(R, g.quats)
            dirs = m_local + Rd.T @ offset  # d_l = R^T (mu_w - c)
        parts["means"].append(m_rel)
        parts["quats"].append(q)
        parts["scales"].append(g.scales)
        parts["opac"].append(g.opacities)
        parts["colors"].append(sh_to_color(g.sh_degree, g.sh, dirs, backend=sh_backend).to(g.sh.dtype))
        k = actor_ids.index(aid) if aid != 0 else -1
        parts["groups"].append(torch.full((len(g),), k, dtype=torch.int64, device=device))
    dtype = dtype or torch.float32
    if parts["means"]:
        cat = {k: torch.cat(v, 0) for k, v in parts.items()}
    else:
        z = lambda *s: torch.zeros(*s, dtype=dtype, device=device)
        cat = {"means": z(0, 3).double(), "quats": z(0, 4), "scales": z(0, 3), "opac": z(0), "colors": z(0, 3),
               "groups": torch.zeros(0, dtype=torch.int64, device=device)}
    return Composed(cat["means"], cat["quats"], cat["scales"], cat["opac"], cat["colors"], cat["groups"],
                    view0.to(device), actor_ids, culled, dtype)
