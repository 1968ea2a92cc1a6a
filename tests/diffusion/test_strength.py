"""The restorer's strength: the sampler moves its start by that share of the correction, and the
share fitted on held-out pairs is the least-squares one (against a float64 grid search)."""

from dataclasses import replace

import numpy as np
import pytest
import torch
from safetensors.numpy import save_file

from symdrive_core.diffusion.config import SAMPLERS
from symdrive_core.diffusion.data import PairSet
from symdrive_core.diffusion.models import BuiltinRestorer, load_builtin, save_builtin
from symdrive_core.diffusion.sampler import restore_image
from symdrive_core.diffusion.strength import fit_strength, held_out_samples
from symdrive_core.diffusion.train import TrainConfig, train_restorer
from symdrive_core.diffusion.unet import UNet, UNetConfig
from symdrive_core.errors import InputError
from tests.diffusion.test_guided import guided_pairs

SAMPLER = SAMPLERS["builtin"]


def restorer(seed=0) -> BuiltinRestorer:
    torch.manual_seed(seed)
    net = UNet(UNetConfig(width=8, mults=(1, 2), guide_channels=4))
    with torch.no_grad():  # a random network's correction, large enough to matter
        for p in net.parameters():
            p.mul_(3.0)
    return BuiltinRestorer(net.eval())


def random_pairs(path, frames=(0, 1, 2, 3), h=16, w=24, seed=0, sensor=False):
    """One pair, one degraded start and one warp (left half seen) per frame, all random colour;
    ``sensor``: and one pair per frame whose target a rig's second camera recorded."""
    rng = np.random.default_rng(seed)
    n = len(frames)
    img = lambda k: rng.integers(0, 256, (k, h, w, 3), dtype=np.uint8)
    mask = np.zeros((n, h, w), np.uint8)
    mask[:, :, : w // 2] = 1
    f = np.asarray(frames, np.int32)
    data = {"left": img(n), "target": img(n), "right": img(n), "offset": np.ones(n, np.float32), "frame": f,
            "degraded": img(n), "degraded_frame": f, "warp": img(n), "warp_mask": mask, "warp_frame": f}
    if sensor:
        data |= {"sensor_left": img(n), "sensor_target": img(n), "sensor_right": img(n),
                 "sensor_offset": np.ones(n, np.float32), "sensor_view": np.arange(n, dtype=np.int32),
                 "sensor_start": img(n), "sensor_warp": img(n), "sensor_warp_mask": mask, "sensor_frame": f}
    save_file(data, str(path))
    return path


def with_targets(path, pairs: PairSet, model, share: float, seed=1, keep_warp: bool = True):
    """Rewrite the targets as ``start + share * (restored - start)`` plus a little noise (the view
    keeping the warp where it was seen, or not)."""
    from safetensors.numpy import load_file

    data = load_file(str(path))
    rng = np.random.default_rng(seed)
    n = len(data["target"])
    for i, (left, right, start, guide, _, _) in enumerate(held_out_samples(pairs, guided=True)):
        restored = restore_image(model, left, right, start, replace(SAMPLER, strength=1.0, keep_warp=keep_warp), guide)
        target = (start + share * (restored - start))[0].permute(1, 2, 0).numpy()
        target = target + rng.normal(0, 0.01, target.shape)
        key, k = ("target", i) if i < n else ("sensor_target", i - n)
        data[key][k] = np.clip(np.rint(target * 255), 0, 255).astype(np.uint8)
    save_file(data, str(path))
    return path


def grid_psnrs(model, pairs: PairSet, shares: np.ndarray) -> np.ndarray:
    """PSNR over all held-out pixels of the view at each share, in float64."""
    se, pixels = np.zeros(len(shares)), 0
    for left, right, start, guide, target, _ in held_out_samples(pairs, guided=True):
        r = restore_image(model, left, right, start, replace(SAMPLER, strength=1.0), guide).double().numpy()
        x, y = start.double().numpy(), target.double().numpy()
        for k, s in enumerate(shares):
            se[k] += ((x + s * (r - x) - y) ** 2).sum()
        pixels += y.size
    return 10 * np.log10(pixels / se)


@pytest.mark.parametrize("share", [0.4, 0.75])
def test_fitted_strength_is_the_least_squares_share(tmp_path, share):
    model = restorer()
    path = random_pairs(tmp_path / "p.safetensors")
    with_targets(path, PairSet(path), model, share)
    held = PairSet(path, [1, 3], held_out=True)
    fit = fit_strength(model, held, SAMPLER, guided=True)
    shares = np.linspace(0, 1, 2001)
    psnrs = grid_psnrs(model, held, shares)
    assert fit.samples == 2
    assert abs(fit.strength - shares[np.argmax(psnrs)]) <= 1e-3
    assert abs(fit.strength - share) < 0.05
    assert fit.fitted_psnr == pytest.approx(np.interp(fit.strength, shares, psnrs), abs=1e-3)
    assert fit.start_psnr == pytest.approx(psnrs[0], abs=1e-6)
    assert fit.restored_psnr == pytest.approx(psnrs[-1], abs=1e-6)
    assert fit.fitted_psnr >= max(fit.start_psnr, fit.restored_psnr)


@pytest.mark.parametrize("keep", [True, False])
def test_a_second_cameras_held_out_pairs_choose_whether_views_keep_the_warp(tmp_path, keep):
    model = restorer()
    path = random_pairs(tmp_path / "p.safetensors", sensor=True)
    with_targets(path, PairSet(path), model, 0.75, keep_warp=keep)
    fit = fit_strength(model, PairSet(path, [0, 1, 2, 3], held_out=True), SAMPLER, guided=True)
    assert fit.samples == 8 and fit.lateral_samples == 4
    assert fit.keep_warp is keep and (fit.kept_psnr > fit.free_psnr) is keep
    assert abs(fit.strength - 0.75) < 0.05


def test_without_lateral_truth_views_keep_the_warp(tmp_path):
    # held out at the recorded camera the restorer is on its own ground; whether to keep the warp
    # sideways is not what these frames can say
    model = restorer()
    path = random_pairs(tmp_path / "p.safetensors")
    with_targets(path, PairSet(path), model, 0.75, keep_warp=False)
    fit = fit_strength(model, PairSet(path, [0, 1, 2, 3], held_out=True), SAMPLER, guided=True)
    assert fit.keep_warp is True and fit.lateral_samples == 0 and fit.kept_psnr is None and fit.free_psnr is None


def test_a_correction_away_from_the_truth_gets_no_strength(tmp_path):
    model = restorer()
    path = random_pairs(tmp_path / "p.safetensors")
    with_targets(path, PairSet(path), model, -0.5)
    fit = fit_strength(model, PairSet(path, [0, 1, 2, 3], held_out=True), SAMPLER, guided=True)
    assert fit.strength == 0.0 and fit.fitted_psnr == pytest.approx(fit.start_psnr)


def test_nothing_held_out_fits_nothing(tmp_path):
    path = random_pairs(tmp_path / "p.safetensors")
    assert fit_strength(restorer(), PairSet(path, [], held_out=True), SAMPLER, guided=True) is None


def test_the_sampler_moves_its_start_by_the_strength():
    model = restorer()
    g = torch.Generator().manual_seed(0)
    left, right, init = (torch.rand(1, 3, 16, 24, generator=g) for _ in range(3))
    guide = torch.cat([init, torch.zeros(1, 1, 16, 24)], dim=1)  # no frame saw it: all of it restored
    full = restore_image(model, left, right, init, replace(SAMPLER, strength=1.0), guide)
    assert not torch.allclose(full, init, atol=1e-3)
    assert torch.equal(restore_image(model, left, right, init, replace(SAMPLER, strength=0.0), guide), init)
    half = restore_image(model, left, right, init, replace(SAMPLER, strength=0.5), guide)
    assert torch.allclose(half, (init + full) / 2, atol=1e-6)
    model.strength = 0.5  # the restorer's own strength where the sampler names none
    assert torch.equal(restore_image(model, left, right, init, SAMPLER, guide), half)
    assert torch.equal(restore_image(model, left, right, init, replace(SAMPLER, strength=1.0), guide), full)


def test_weights_carry_their_strength(tmp_path):
    net = restorer().net
    save_builtin(tmp_path / "w.safetensors", net, {"strength": 0.3})
    assert load_builtin(tmp_path / "w.safetensors").strength == pytest.approx(0.3)
    save_builtin(tmp_path / "plain.safetensors", net)
    assert load_builtin(tmp_path / "plain.safetensors").strength == 1.0
    save_builtin(tmp_path / "bad.safetensors", net, {"strength": 1.5})
    with pytest.raises(InputError, match="meta.strength"):
        load_builtin(tmp_path / "bad.safetensors")


def test_weights_carry_whether_their_views_keep_the_warp(tmp_path):
    net = restorer().net
    save_builtin(tmp_path / "w.safetensors", net, {"strength": 0.3, "keep_warp": False})
    assert load_builtin(tmp_path / "w.safetensors").keep_warp is False
    save_builtin(tmp_path / "plain.safetensors", net)
    assert load_builtin(tmp_path / "plain.safetensors").keep_warp is True
    save_builtin(tmp_path / "bad.safetensors", net, {"keep_warp": "yes"})
    with pytest.raises(InputError, match="meta.keep_warp"):
        load_builtin(tmp_path / "bad.safetensors")


def test_the_sampler_keeps_the_warp_as_the_restorer_records_unless_told():
    model = restorer()
    g = torch.Generator().manual_seed(0)
    left, right, init, warp = (torch.rand(1, 3, 16, 24, generator=g) for _ in range(4))
    mask = torch.zeros(1, 1, 16, 24)
    mask[..., :12] = 1
    guide = torch.cat([warp, mask], dim=1)
    kept = restore_image(model, left, right, init, SAMPLER, guide)
    assert torch.equal(kept[..., :12], warp[..., :12])  # seen: the warp
    assert not torch.allclose(kept[..., 12:], warp[..., 12:], atol=1e-2)
    model.keep_warp = False
    free = restore_image(model, left, right, init, SAMPLER, guide)
    assert not torch.allclose(free[..., :12], warp[..., :12], atol=1e-2)
    assert torch.equal(free[..., 12:], kept[..., 12:])
    assert torch.equal(restore_image(model, left, right, init, replace(SAMPLER, keep_warp=True), guide), kept)


def test_held_out_frames_leave_training(tmp_path):
    path = guided_pairs(tmp_path / "p.safetensors")  # frames 0, 0, 1, 1; warps of frames 1, 0
    train, held = PairSet(path, [1]), PairSet(path, [1], held_out=True)
    assert len(train) == len(held) == 2
    assert train.warp_of == [1, 1] and held.warp_of == [0, 0]
    cfg = TrainConfig(steps=1, batch=2, crop=16, width=8, mults=(1, 2), guide=True, holdout_frames=(0, 1))
    with pytest.raises(InputError, match="no pairs left"):
        train_restorer(path, tmp_path / "out", cfg, progress=False)
