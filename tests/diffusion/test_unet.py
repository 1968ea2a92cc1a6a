import torch

from symdrive_core.diffusion.models import load_builtin, save_builtin
from symdrive_core.diffusion.unet import UNet, UNetConfig

from .helpers import TINY, tiny_builtin


def test_any_frame_size_in_any_size_out():
    net = tiny_builtin().net
    for h, w in ((16, 16), (37, 53), (9, 144)):
        x = torch.rand(2, 3, h, w)
        assert net(x, torch.rand(2), x, x).shape == (2, 3, h, w)


def test_fresh_network_predicts_zero_and_depends_on_every_input():
    v_net = UNet(UNetConfig(width=8, mults=(1, 2), output="v"))
    r = [torch.rand(1, 3, 8, 8) for _ in range(3)]
    assert float(v_net(r[0], torch.rand(1), r[1], r[2]).detach().abs().max()) == 0.0
    net = tiny_builtin().net
    g = torch.Generator().manual_seed(0)
    a, b, c = (torch.rand(1, 3, 16, 16, generator=g) for _ in range(3))
    t = torch.tensor([0.5])
    base = net(b, t, a, c)
    for changed in (net(b, torch.tensor([0.9]), a, c), net(b, t, c, c), net(b, t, a, a), net(a, t, a, c)):
        assert not torch.allclose(base, changed)


def test_weights_round_trip_with_their_config(tmp_path):
    model = tiny_builtin(3)
    path = save_builtin(tmp_path / "w.safetensors", model.net, {"steps": 1})
    loaded = load_builtin(path)
    assert loaded.net.config == TINY
    x = torch.rand(1, 3, 12, 12)
    assert torch.equal(loaded.net(x, torch.tensor([0.3]), x, x), model.net(x, torch.tensor([0.3]), x, x))


def test_config_json_round_trip():
    cfg = UNetConfig(width=16, mults=(1, 2, 4))
    assert UNetConfig.from_json(cfg.to_json()) == cfg


def _x0(net, z, t, left, right):
    tt = torch.tensor([t])
    return z - t * net(z, tt, left, right)


def test_fresh_skip_network_blends_the_noisy_state_and_the_condition_mean():
    net = UNet(TINY)
    g = torch.Generator().manual_seed(1)
    z, left, right = (torch.rand(1, 3, 8, 8, generator=g) * 2 - 1 for _ in range(3))
    # nearly clean: the state itself; nearly pure noise: the mean of the two conditions
    assert torch.allclose(_x0(net, z, 1e-3, left, right), z, atol=1e-3)
    assert torch.allclose(_x0(net, z, 0.999, left, right), (left + right) / 2, atol=1e-3)
    # in between, the least-squares blend with weight s^2 (1 - t) / D on the state
    s2, t = TINY.cond_sigma**2, 0.5
    d = (1 - t) ** 2 * s2 + t**2
    expected = (s2 * (1 - t) * z + t**2 * (left + right) / 2) / d
    assert torch.allclose(_x0(net, z, t, left, right), expected, atol=1e-5)


def test_loss_weight_makes_the_correction_unit_scale():
    t = torch.tensor([0.1, 0.5, 0.9])
    assert torch.equal(UNet(UNetConfig(width=8, mults=(1, 2), output="v")).loss_weight(t), torch.ones(3))
    s2 = TINY.cond_sigma**2
    assert torch.allclose(UNet(TINY).loss_weight(t), ((1 - t) ** 2 * s2 + t**2) / s2)


def test_checkpoints_without_an_output_field_predict_velocity():
    d = UNetConfig(width=8, mults=(1, 2)).to_json()
    del d["output"]
    assert UNetConfig.from_json(d).output == "v"


def test_inference_in_channels_last_is_the_training_layouts_velocity():
    """Evaluation runs NHWC (faster on the CPU), training NCHW: the same numbers to float32 rounding,
    on the shipped guided network at an odd size (padding) with its guide."""
    from symdrive_core.diffusion.defaults import GUIDED_WEIGHTS

    net = load_builtin(GUIDED_WEIGHTS).net
    g = torch.Generator().manual_seed(0)
    z, left, right = (torch.rand(1, 3, 45, 70, generator=g) * 2 - 1 for _ in range(3))
    guide = torch.rand(1, 4, 45, 70, generator=g) * 2 - 1
    t = torch.full((1,), 0.2)
    with torch.no_grad():
        nhwc = net.eval()(z, t, left, right, guide)
        nchw = net.train()(z, t, left, right, guide)
    assert nhwc.is_contiguous() and nhwc.shape == z.shape
    assert (nhwc - nchw).abs().max() <= 1e-4 * nchw.abs().max()
