import numpy as np
import pytest
import torch
from safetensors.numpy import load_file

from symdrive_core.diffusion.cycle import cycle_renders, shifted_views
from symdrive_core.diffusion.data import PairSet, make_pairs
from symdrive_core.metrics import psnr
from symdrive_core.optim.reconstruct import ReconstructConfig, load_views
from symdrive_core.scene import load_manifest
from symdrive_core.scene.camera import CameraView
from symdrive_core.splat.render import SplatRenderer
from tests.optim.conftest import synthetic_package  # noqa: F401  (fixture)

CYCLE = ReconstructConfig(iters=80, densify_from=40, densify_every=40, sky_points=0)
QUICK = ReconstructConfig(iters=20, densify_from=40, sky_points=0)  # where only the layout is tested


def test_shifted_views_render_the_camera_moved_right(synthetic_package):  # noqa: F811
    root, truth = synthetic_package
    m = load_manifest(root)
    views = load_views(m, [0, 3])
    render = SplatRenderer(truth)
    moved = shifted_views(views, render, 1.5)
    for v, s in zip(views, moved):
        c2w = np.linalg.inv(v.viewmat.numpy().astype(np.float64))
        c2w_s = np.linalg.inv(s.viewmat.numpy().astype(np.float64))
        assert np.allclose(c2w_s[:3, 3] - c2w[:3, 3], 1.5 * c2w[:3, 0], atol=1e-5)
        assert np.allclose(c2w_s[:3, :3], c2w[:3, :3], atol=1e-6)
        assert s.depth is None and s.frame == v.frame
        expect = render(v.camera.shifted(1.5))
        assert np.array_equal(s.image.numpy(), expect)


def test_cycle_renders_are_aligned_with_the_recorded_frames(synthetic_package):  # noqa: F811
    root, truth = synthetic_package
    m = load_manifest(root)
    frames = [0, 2, 3, 5]
    out = cycle_renders(m, truth, 1.0, frames, CYCLE, progress=False)
    assert out.shape == (4, 32, 48, 3) and out.dtype == np.uint8
    render = SplatRenderer(truth)
    for k, i in enumerate(frames):
        view = CameraView.of_frame(m.cameras[0], i)
        recorded, shifted = render(view), render(view.shifted(1.0))
        cycled = out[k] / 255.0
        # the cycle render is the recorded view, degraded: closer to it than the view 1 m away,
        # yet not the recorded image itself
        assert psnr(cycled, recorded) > psnr(shifted, recorded) + 3.0
        assert psnr(cycled, recorded) < 45.0
    with pytest.raises(ValueError, match="non-zero"):
        cycle_renders(m, truth, 0.0, frames, CYCLE, progress=False)


def test_pairs_carry_degraded_starts_and_batches_use_them(synthetic_package, tmp_path):  # noqa: F811
    root, truth = synthetic_package
    m = load_manifest(root)
    path = make_pairs(m, truth, [0.5], tmp_path / "p.safetensors", frames=[0, 3], cycle_offsets=[-1.0, 1.0],
                      cycle_config=QUICK, progress=False)
    data = load_file(str(path))
    assert data["degraded"].shape == (4, 32, 48, 3)
    assert data["degraded_frame"].tolist() == [0, 3, 0, 3]
    assert data["degraded_offset"].tolist() == [-1.0, -1.0, 1.0, 1.0]
    pairs = PairSet(path)
    assert pairs.has_degraded and pairs.starts == [[0, 2], [1, 3]]
    g = torch.Generator().manual_seed(0)
    left, target, right, start, _ = pairs.batch(16, 48, g, degraded_fraction=0.0)
    assert torch.equal(start, target)
    left, target, right, start, _ = pairs.batch(32, 48, torch.Generator().manual_seed(1), degraded_fraction=1.0)
    for k in range(32):  # full-width crops: each start is a degraded image of the target's frame
        i = next(i for i in range(2) if torch.equal(pairs.target[i], target[k])
                 or torch.equal(pairs.target[i].flip(-1), target[k]))
        mirrored = not torch.equal(pairs.target[i], target[k])
        options = [pairs.degraded[j].flip(-1) if mirrored else pairs.degraded[j] for j in pairs.starts[i]]
        assert any(torch.equal(start[k], o) for o in options)
    with pytest.raises(ValueError, match="non-zero"):
        make_pairs(m, truth, [0.5], tmp_path / "x.safetensors", cycle_offsets=[0.0], progress=False)
