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
    assert (
        float(
            UNet(TINY)(torch.rand(1, 3, 8, 8), torch.rand(1), torch.rand(1, 3, 8, 8), torch.rand(1, 3, 8, 8))
            .abs()
            .max()
        )
        == 0.0
    )
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
