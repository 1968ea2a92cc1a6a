"""The restorer with the geometry-guided warp and its mask as a condition: the zero-initialised
extension, training pairs whose warp never sees its own target, and old weights beside new ones."""

from types import SimpleNamespace

import numpy as np
import pytest
import torch
from safetensors.numpy import save_file

from symdrive_core import conventions
from symdrive_core.diffusion import warp as warp_module
from symdrive_core.diffusion.data import PairSet, pair_warper, pair_warps
from symdrive_core.diffusion.models import BuiltinRestorer, load_builtin, save_builtin
from symdrive_core.diffusion.restore import LateralChain
from symdrive_core.diffusion.sampler import SamplerConfig
from symdrive_core.diffusion.train import TrainConfig, train_restorer
from symdrive_core.diffusion.unet import UNet, UNetConfig, with_guide
from symdrive_core.scene.camera import CameraView
from tests.diffusion.test_restore import DepthOffsetRenderer, OffsetRenderer
from tests.diffusion.test_warp import H, K, W, down_camera, path_warper

SMALL = UNetConfig(width=8, mults=(1, 2))


def trained_like(config=SMALL) -> UNet:
    """A network with every weight random (a fresh one has a zero output layer)."""
    torch.manual_seed(0)
    net = UNet(config)
    with torch.no_grad():
        for p in net.parameters():
            p.normal_(0.0, 0.2)
    return net


def test_zero_initialised_extension_equals_the_base_network():
    base = trained_like()
    ext = with_guide(base)
    assert ext.config.guide_channels == 4 and ext.inp.weight.shape[1] == 13
    z, left, right = (torch.rand(2, 3, 20, 28) for _ in range(3))
    t = torch.tensor([0.3, 0.8])
    guide = torch.rand(2, 4, 20, 28)
    with torch.no_grad():
        assert torch.equal(ext(z, t, left, right, guide), base(z, t, left, right))
        ext.inp.weight[:, 9:] += 0.1  # the guide inputs are live once trained
        assert not torch.allclose(ext(z, t, left, right, guide), base(z, t, left, right))
    with pytest.raises(ValueError, match="guide"):
        ext(z, t, left, right)
    with pytest.raises(ValueError, match="already"):
        with_guide(ext)


def test_old_and_guided_weights_load_as_their_own_variant(tmp_path):
    base = trained_like()
    save_builtin(tmp_path / "old.safetensors", base)
    old = load_builtin(tmp_path / "old.safetensors")
    assert old.guide_channels == 0
    z = torch.rand(1, 3, 16, 16)
    t = torch.tensor([0.5])
    with torch.no_grad():  # an unguided network ignores a guide it is given
        assert torch.equal(old.velocity(z, t, z, z, torch.rand(1, 4, 16, 16)), old.velocity(z, t, z, z))
    save_builtin(tmp_path / "geo.safetensors", with_guide(base))
    geo = load_builtin(tmp_path / "geo.safetensors")
    assert geo.guide_channels == 4 and geo.net.inp.weight.shape[1] == 13


def test_a_pair_warp_never_uses_its_own_frame_or_frames_outside_the_pairs(monkeypatch):
    warper = path_warper()
    for s in (4, 5):  # 4: the target; 5: a frame the pairs do not train on
        warper.sources[s].image = np.full((H, W, 3), np.nan)
    monkeypatch.setattr(warp_module, "package_warper", lambda *a, **k: warper)
    frames = [SimpleNamespace(K=K, camera_to_world=down_camera(float(i)),
                              world_to_camera=conventions.invert_rigid(down_camera(float(i)))) for i in range(9)]
    cam = SimpleNamespace(frames=frames, width=W, height=H)
    image, mask = pair_warps(pair_warper(None, None, cam, [3, 4, 6]), cam, [3, 4, 6], DepthOffsetRenderer())
    assert image.shape == (3, H, W, 3) and mask.shape == (3, H, W)
    assert np.isfinite(image[1]).all() and mask[1].mean() > 0.5  # frame 4's warp: from frames 3 and 6 alone
    assert set(warper.sources) == {3, 4, 6}


def guided_pairs(path, n=4, h=16, w=20):
    """Target 0.8, degraded starts 0.2, warps 0.6 on the left half (the mask), two frames."""
    full = lambda v, k: np.full((k, h, w, 3), v, np.uint8)
    mask = np.zeros((2, h, w), np.uint8)
    mask[:, :, : w // 2] = 1
    save_file({"left": full(100, n), "target": full(204, n), "right": full(150, n),
               "offset": np.ones(n, np.float32), "frame": np.array([0, 0, 1, 1], np.int32),
               "degraded": full(51, 2), "degraded_frame": np.array([0, 1], np.int32),
               "warp": full(153, 2), "warp_mask": mask, "warp_frame": np.array([1, 0], np.int32)}, str(path))
    return path


def test_guided_batches_fill_the_warp_from_a_degraded_start_never_the_target(tmp_path):
    data = PairSet(guided_pairs(tmp_path / "p.safetensors"))
    assert data.has_warps and data.warp_of == [1, 1, 0, 0]
    for fraction in (0.0, 1.0):
        left, target, right, start, guide = data.batch(16, 16, torch.Generator().manual_seed(0), fraction)
        assert guide.shape == (16, 4, 16, 16)
        warp, mask = guide[:, :3], guide[:, 3:]
        on = mask.expand_as(warp) > 0
        assert torch.allclose(warp[on], torch.tensor(0.6)) and torch.allclose(warp[~on], torch.tensor(0.2))
        assert torch.equal(start, warp) if fraction else torch.equal(start, target)


def test_unguided_batches_of_a_file_with_warps_start_from_the_cycle_renders(tmp_path):
    data = PairSet(guided_pairs(tmp_path / "p.safetensors"), warps=False)  # one file serves both restorers
    assert not data.has_warps
    left, target, right, start, guide = data.batch(16, 16, torch.Generator().manual_seed(0), 1.0)
    assert guide is None and torch.allclose(start, torch.tensor(0.2))


def test_guided_training_extends_unguided_init_weights(tmp_path):
    pairs = guided_pairs(tmp_path / "p.safetensors")
    cfg = TrainConfig(steps=2, batch=2, crop=16, width=8, mults=(1, 2), checkpoint_every=2)
    train_restorer(pairs, tmp_path / "base", cfg, progress=False)
    cfg.init, cfg.guide = str(tmp_path / "base" / "restorer.safetensors"), True
    record = train_restorer(pairs, tmp_path / "geo", cfg, progress=False)
    assert record["config"]["unet"]["guide_channels"] == 4
    assert load_builtin(tmp_path / "geo" / "restorer.safetensors").guide_channels == 4


class SeenWarper:
    """A stand-in warper: the render plus 0.25, seen by some frame in the first ``columns`` columns."""

    config = SimpleNamespace(min_alpha=0.5)

    def __init__(self, columns: int):
        self.columns = columns

    def warp(self, frame, K, c2w, width, height, raw, depth):
        mask = np.zeros((height, width), bool)
        mask[:, : self.columns] = True
        return SimpleNamespace(image=raw + 0.25, mask=mask)


def test_chain_gives_a_guided_restorer_the_warp_and_its_mask():
    seen = []

    class Guided(BuiltinRestorer):
        def velocity(self, z, t, left, right, guide=None):
            seen.append(guide)
            return super().velocity(z, t, left, right, guide)

    restorer = Guided(with_guide(UNet(SMALL)))
    c = LateralChain(restorer, DepthOffsetRenderer(), np.full((4, 6, 3), 0.5, np.float32),
                     CameraView(np.eye(4), np.eye(3), 6, 4), SamplerConfig(steps=1, n_start=0), SeenWarper(2), 0)
    c.by_method(0.5, "geo_single_view")
    raw = OffsetRenderer()(CameraView(np.eye(4), np.eye(3), 6, 4).shifted(0.5))
    expect_warp = torch.from_numpy(raw + 0.25).permute(2, 0, 1) * 2 - 1
    assert torch.allclose(seen[0][0, :3], expect_warp)
    assert seen[0][0, 3, :, :2].eq(1).all() and seen[0][0, 3, :, 2:].eq(-1).all()
    c.by_method(0.5, "single_view")  # unguided: the render, nothing seen
    assert seen[1][0, 3].eq(-1).all()


def test_shipped_guided_weights_serve_the_guided_methods_only(tmp_path, monkeypatch):
    from symdrive_core.diffusion import models

    save_builtin(tmp_path / "geo.safetensors", with_guide(trained_like()))
    monkeypatch.setattr(models, "GUIDED_WEIGHTS", tmp_path / "absent.safetensors")
    assert models.load_restorer().guided is None  # no guided weights shipped: one restorer for all
    monkeypatch.setattr(models, "GUIDED_WEIGHTS", tmp_path / "geo.safetensors")
    base = models.load_restorer()
    assert base.guide_channels == 0 and base.guided.guide_channels == 4
    assert models.load_restorer(weights=tmp_path / "geo.safetensors").guided is None  # explicit weights: those
    used = []
    for r in (base, base.guided):
        r.velocity = lambda z, t, left, right, guide=None, r=r: used.append((r, guide)) or torch.zeros_like(z)
    c = LateralChain(base, DepthOffsetRenderer(), np.full((4, 6, 3), 0.5, np.float32),
                     CameraView(np.eye(4), np.eye(3), 6, 4), SamplerConfig(steps=1, n_start=0), SeenWarper(6), 0)
    c.by_method(0.5, "single_view")
    c.by_method(0.5, "geo_single_view")
    assert [(r is base.guided, g is not None) for r, g in used] == [(False, False), (True, True)]



@pytest.mark.parametrize("keep", [True, False])
def test_a_guided_view_keeps_the_warp_where_frames_saw_the_ground(keep):
    restorer = BuiltinRestorer(with_guide(trained_like()))
    recorded = np.full((4, 6, 3), 0.5, np.float32)
    c = LateralChain(restorer, DepthOffsetRenderer(), recorded, CameraView(np.eye(4), np.eye(3), 6, 4),
                     SamplerConfig(steps=2, n_start=1, noise_free=True, keep_warp=keep), SeenWarper(2), 0)
    for method in ("geo_single_view", "geo_ar_d0.5"):
        view, warp = c.by_method(1.0, method), c.warp(1.0)
        seen = np.abs(view[:, :2] - warp[:, :2]).max()
        assert (seen < 1e-6) if keep else (seen > 1e-3), method
        assert np.abs(view[:, 2:] - warp[:, 2:]).max() > 1e-3  # what no frame saw: the restorer's
    unguided = c.by_method(1.0, "single_view")  # its guide is the render with nothing seen
    assert np.abs(unguided[:, :2] - c.warp(1.0)[:, :2]).max() > 1e-3
