"""Composition of background and moving actors in one rasterizer call."""

from __future__ import annotations

import math

import numpy as np
import torch

from symdrive_core.gaussians import Gaussians
from symdrive_core.rotations import matrix_to_quat
from symdrive_core.splat import GaussianTensors, Layer, rasterize, render_layers
from symdrive_core.splat.compose import rotate_quats
from symdrive_core.splat.projection import quat_to_rotmat

from .scenes import K_from_fov, look_at

W, H = 64, 48


def _gaussians(n, deg, seed, center=(0.0, 0.0, 0.0), spread=1.0):
    rng = np.random.default_rng(seed)
    return Gaussians(means=(np.asarray(center) + spread * rng.normal(size=(n, 3))).astype(np.float32),
                     quats=rng.normal(size=(n, 4)).astype(np.float32),
                     log_scales=(rng.normal(size=(n, 3)) * 0.3 - 2.0).astype(np.float32),
                     opacity_logits=rng.normal(size=n).astype(np.float32) + 1.0,
                     sh=(0.4 * rng.normal(size=(n, (deg + 1) ** 2, 3))).astype(np.float32))


def _yaw(a, dtype=torch.float64):
    return torch.tensor([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1.0]], dtype=dtype)


def _setup(dtype=torch.float64, origin=(0.0, 0.0, 0.0)):
    o = np.asarray(origin)
    V = torch.tensor(look_at(o + (0, 0, 1.5), o + (10, 0, 1.0)), dtype=dtype)
    K = K_from_fov(W, H, 60.0, dtype)
    bg = GaussianTensors.from_gaussians(_gaussians(200, 1, 1, o + (12, 0, 1), 3.0), dtype=dtype)
    car = GaussianTensors.from_gaussians(_gaussians(80, 3, 2, spread=0.7), dtype=dtype)
    return V, K, bg, car


def test_actor_equals_manual_transform_with_local_sh():
    V, K, bg, car = _setup()
    R, T = _yaw(0.6), torch.tensor([8.0, 1.0, 0.8], dtype=torch.float64)
    out = render_layers([Layer(bg, None, None, 0), Layer(car, R, T, 7)], V, K, W, H)
    # manual: world means, composed quaternions, colours from SH in the car's frame
    mw = car.means @ R.T + T
    qw = rotate_quats(R, car.quats)
    cam = -(V[:3, :3].T @ V[:3, 3])
    from symdrive_core.splat.sh import sh_to_color
    col_car = sh_to_color(3, car.sh, (mw - cam) @ R)  # R^T (mu_w - c) as row vectors
    col_bg = sh_to_color(1, bg.sh, bg.means - cam)
    rgb, alpha, info = rasterize(torch.cat([bg.means, mw]), torch.cat([bg.quats, qw]),
                                 torch.cat([bg.scales, car.scales]), torch.cat([bg.opacities, car.opacities]),
                                 torch.cat([col_bg, col_car]), V, K, W, H, render_depth=True)
    assert float(out["instance"].max()) > 0.5
    torch.testing.assert_close(out["rgb"], rgb, atol=1e-9, rtol=0)
    torch.testing.assert_close(out["alpha"], alpha, atol=1e-9, rtol=0)
    torch.testing.assert_close(out["depth"], info["depth"], atol=1e-7, rtol=0)
    assert out["actor_ids"] == [7] and out["culled"] == []


def test_rigid_motion_of_car_and_camera_together_changes_nothing():
    """SH in the local frame: moving the car and the camera by the same rigid motion is invisible."""
    V, K, _, car = _setup()
    R0, T0 = _yaw(0.3), torch.tensor([8.0, 0.5, 0.8], dtype=torch.float64)
    a = render_layers([Layer(car, R0, T0, 1)], V, K, W, H)
    M = torch.eye(4, dtype=torch.float64)
    M[:3, :3], M[:3, 3] = _yaw(1.1), torch.tensor([30.0, -5.0, 2.0], dtype=torch.float64)
    V2 = V @ torch.linalg.inv(M)
    b = render_layers([Layer(car, M[:3, :3] @ R0, M[:3, :3] @ T0 + M[:3, 3], 1)], V2, K, W, H)
    assert float(a["alpha"].max()) > 0.5
    torch.testing.assert_close(a["rgb"], b["rgb"], atol=1e-8, rtol=0)
    torch.testing.assert_close(a["instance"], b["instance"], atol=1e-8, rtol=0)


def test_instance_masks_sum_to_alpha_and_culling():
    V, K, _, car = _setup()
    layers = [Layer(car, _yaw(0.2), torch.tensor([9.0, -1.5, 0.8], dtype=torch.float64), 1),
              Layer(car, _yaw(-0.4), torch.tensor([12.0, 2.0, 0.8], dtype=torch.float64), 2),
              Layer(car, None, torch.tensor([-20.0, 0.0, 0.8], dtype=torch.float64), 3)]  # behind the camera
    out = render_layers(layers, V, K, W, H)
    assert out["actor_ids"] == [1, 2, 3] and out["culled"] == [3]
    inst = out["instance"]
    assert float(inst[..., 0].max()) > 0.3 and float(inst[..., 1].max()) > 0.3
    assert float(inst[..., 2].abs().max()) == 0.0
    torch.testing.assert_close(inst.sum(-1, keepdim=True), out["alpha"], atol=1e-10, rtol=0)
    # the culled actor renders nothing even without culling
    full = render_layers(layers, V, K, W, H, cull=False)
    torch.testing.assert_close(full["rgb"], out["rgb"], atol=1e-12, rtol=0)


def test_gradients_reach_actor_colour_and_opacity():
    V, K, bg, car = _setup(torch.float32)
    sh = car.sh.clone().requires_grad_(True)
    logit = torch.logit(car.opacities.clamp(1e-4, 1 - 1e-4)).clone().requires_grad_(True)
    car2 = GaussianTensors(car.means, car.quats, car.scales, torch.sigmoid(logit), sh, 3)
    out = render_layers([Layer(bg, None, None, 0), Layer(car2, _yaw(0.5), torch.tensor([8.0, 0.0, 0.8]), 4)],
                        V, K, W, H, background=torch.tensor([0.5, 0.5, 0.5]))
    (out["rgb"].mean() + out["instance"].mean()).backward()
    assert torch.isfinite(sh.grad).all() and float(sh.grad.abs().max()) > 0
    assert torch.isfinite(logit.grad).all() and float(logit.grad.abs().max()) > 0


def test_far_from_origin_matches_origin():
    """Scene and camera 1e5 m away render like the same scene at the origin (float32 inputs)."""
    V0, K, bg0, car0 = _setup(torch.float32)
    # means on a 1/64 m grid stay exact in float32 at 1e5 m (the spacing of float32 there is 1/128)
    bg0 = GaussianTensors(torch.round(bg0.means * 64) / 64, bg0.quats, bg0.scales, bg0.opacities, bg0.sh, 1)
    off = np.array([1e5, -1e5, 0.0])
    V1 = torch.tensor(look_at(off + (0, 0, 1.5), off + (10, 0, 1.0)), dtype=torch.float64)  # cameras: float64
    bg1 = GaussianTensors((bg0.means.double() + torch.tensor(off)).float(), bg0.quats, bg0.scales, bg0.opacities,
                          bg0.sh, 1)
    assert torch.equal(bg1.means.double() - torch.tensor(off), bg0.means.double())
    R, T = _yaw(0.6, torch.float32), torch.tensor([8.0, 1.0, 0.8])
    a = render_layers([Layer(bg0, None, None, 0), Layer(car0, R, T, 1)], V0, K.float(), W, H)
    b = render_layers([Layer(bg1, None, None, 0), Layer(car0, R, T.double() + torch.tensor(off), 1)], V1, K.float(),
                      W, H)
    assert float(a["alpha"].max()) > 0.5
    torch.testing.assert_close(a["rgb"], b["rgb"], atol=1e-4, rtol=0)



def test_an_actor_at_utm_coordinates_renders_where_its_pose_puts_it():
    """render_scene keeps a package pose's translation in float64: at 4.5e6 m float32 steps are
    half a metre, which moved a car by pixels."""
    from symdrive_core.rotations import quat_from_yaw
    from symdrive_core.scene import Pose
    from symdrive_core.scene.camera import CameraView
    from symdrive_core.splat.render import render_scene

    _, K, _, car = _setup(torch.float32)
    images = []
    for origin in (np.zeros(3), np.array([5.0e5 + 0.3, 4.5e6 + 0.2, 0.0])):
        V = look_at(origin + (0, 0, 1.5), origin + (10, 0, 1.0))
        pose = Pose(origin + (8.03, 1.01, 0.8), quat_from_yaw(0.6))
        images.append(render_scene(None, [(car, pose, 1)], CameraView(V, K.numpy(), W, H))["rgb"])
    assert float(images[0].max()) > 0.2
    torch.testing.assert_close(images[0], images[1], atol=2e-3, rtol=0)

def test_rotate_quats_composes_rotations_and_passes_gradients():
    """q_R (x) q for a batch of unnormalised quaternions, against the rotation matrices, with gradients."""
    R = _yaw(0.9) @ torch.tensor([[1, 0, 0], [0, 0, -1], [0, 1, 0.0]], dtype=torch.float64)
    torch.testing.assert_close(quat_to_rotmat(torch.as_tensor(matrix_to_quat(R.numpy()))[None])[0], R,
                               atol=1e-12, rtol=0)
    q2 = torch.tensor([[0.3, -0.2, 0.5, 0.7], [1.0, 0.0, 0.0, 0.0], [-0.1, 0.9, 0.2, -0.4]], dtype=torch.float64,
                      requires_grad=True)
    q = rotate_quats(R, q2)
    unit = q2.detach() / q2.detach().norm(dim=1, keepdim=True)
    torch.testing.assert_close(quat_to_rotmat(q.detach() / q.detach().norm(dim=1, keepdim=True)),
                               R @ quat_to_rotmat(unit), atol=1e-12, rtol=0)
    torch.testing.assert_close(q.norm(dim=1), q2.detach().norm(dim=1), atol=1e-12, rtol=0)  # a rotation of R^4
    assert torch.autograd.gradcheck(lambda x: rotate_quats(R, x), (q2,))
