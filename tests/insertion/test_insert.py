import numpy as np
import torch

from symdrive_core.insertion.insert import insertion_view
from symdrive_core.scene.place import place
from symdrive_core.splat import rasterize
from symdrive_core.splat.tensors import GaussianTensors

from . import synthetic


def _concat(a, b):
    from symdrive_core.gaussians import Gaussians
    return Gaussians(*(np.concatenate([getattr(a, k), getattr(b, k)]) for k in
                       ("means", "quats", "log_scales", "opacity_logits", "sh")))


def test_cached_view_matches_one_rasterizer_call():
    bg, car, pose, cam = synthetic.ground(), synthetic.car(), synthetic.car_pose(), synthetic.camera()
    view = insertion_view(cam, GaussianTensors.from_gaussians(bg), car, pose)
    rgb, alpha, car_alpha = view.render(torch.as_tensor(car.sh), torch.as_tensor(car.opacity_logits))
    t = GaussianTensors.from_gaussians(_concat(bg, place(car, pose)))
    ref, ref_alpha, _ = rasterize(t.means, t.quats, t.scales, t.opacities, t.sh, torch.as_tensor(cam.world_to_camera,
                                  dtype=torch.float32), torch.as_tensor(cam.K, dtype=torch.float32), cam.width,
                                  cam.height, backend="numba")
    assert view.n_actor_visible > 100
    assert car_alpha.max() > 0.9 and (car_alpha < 1e-3).float().mean() > 0.3
    np.testing.assert_allclose(rgb.numpy(), ref.numpy(), atol=2e-3)
    np.testing.assert_allclose(alpha.numpy(), ref_alpha[..., 0].numpy(), atol=2e-3)


def test_crop_is_the_same_pixels():
    bg, car, pose, cam = synthetic.ground(), synthetic.car(), synthetic.car_pose(), synthetic.camera()
    bgt = GaussianTensors.from_gaussians(bg)
    full, _ = insertion_view(cam, bgt, car, pose).render_numpy(car)
    rows, cols = slice(10, 30), slice(20, 52)
    part, _ = insertion_view(cam.crop(rows, cols), bgt, car, pose).render_numpy(car)
    # Only Gaussians far outside the window differ (the Jacobian's frustum clamp follows the window).
    np.testing.assert_allclose(part, full[rows, cols], atol=2e-3)
    assert np.abs(part - full[rows, cols]).mean() < 1e-4
