import pytest
import torch
from safetensors.torch import save_file

from symdrive_core.diffusion import flow
from symdrive_core.diffusion.flux import (
    FluxRestorer,
    add_lora,
    flux_mu,
    load_flux,
    load_lora,
    pack,
    position_ids,
    save_lora,
    unpack,
)
from symdrive_core.diffusion.models import load_restorer
from symdrive_core.diffusion.sampler import SamplerConfig, restore_image
from symdrive_core.errors import InputError

from .helpers import prompt_embeddings, tiny_flux


def restorer(seed=0):
    transformer, vae = tiny_flux(seed)
    return FluxRestorer(transformer, vae, *prompt_embeddings())


def test_pack_unpack_round_trip_and_ids():
    z = torch.randn(2, 4, 6, 10)
    tokens = pack(z)
    assert tokens.shape == (2, 15, 16)
    assert torch.equal(unpack(tokens, 6, 10), z)
    assert torch.equal(tokens[0, 1], z[0, :, 0:2, 2:4].reshape(-1))  # row 0, column 1: (channel, dy, dx)
    ids = position_ids(2, 6, 10)
    assert ids.shape == (15, 3) and bool((ids[:, 0] == 2).all()) and ids[6].tolist() == [2, 1, 1]
    with pytest.raises(ValueError, match="even"):
        pack(torch.zeros(1, 4, 3, 4))


def test_flux_shift_matches_its_reference_points():
    assert flux_mu(256) == pytest.approx(0.5) and flux_mu(4096) == pytest.approx(1.15)


def test_velocity_reads_the_condition_tokens_and_returns_the_centre_only():
    r = restorer()
    g = torch.Generator().manual_seed(0)
    z, a, b = (torch.randn(1, 4, 8, 8, generator=g) for _ in range(3))
    t = torch.tensor([0.6])
    v = r.velocity(z, t, a, b)
    assert v.shape == z.shape
    assert not torch.allclose(v, r.velocity(z, t, b, a))  # left and right are distinct positions
    assert not torch.allclose(v, r.velocity(z, t, a, a))


def test_same_sampler_runs_with_the_flux_backend():
    r = restorer()
    img = torch.rand(1, 3, 16, 16)
    out = restore_image(r, img, img, img, SamplerConfig(steps=3, n_start=1))
    assert out.shape == img.shape and float(out.min()) >= 0 and float(out.max()) <= 1
    assert r.time_shift((1, 4, 8, 8)) == pytest.approx(flux_mu(16))


def lora_scaled(transformer, seed=1):
    add_lora(transformer, rank=4)
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for name, p in transformer.named_parameters():
            if "lora_B" in name:
                p.copy_(0.1 * torch.randn(p.shape, generator=g))


def test_lora_trains_only_the_adapter_and_survives_save_and_load(tmp_path):
    transformer, vae = tiny_flux()
    base_state = {k: v.clone() for k, v in transformer.state_dict().items()}
    emb = prompt_embeddings()
    z = torch.randn(1, 4, 8, 8)
    base_v = FluxRestorer(transformer, vae, *emb).velocity(z, torch.tensor([0.4]), z, z)
    lora_scaled(transformer)
    r = FluxRestorer(transformer, vae, *emb)
    trainable = r.parameters()
    assert trainable and all(p.requires_grad for p in trainable)
    assert sum(p.numel() for p in trainable) < sum(p.numel() for p in transformer.parameters()) / 5
    loss = flow.flow_loss(lambda zt, t: r.velocity(zt, t, z, z), z, torch.Generator().manual_seed(0))
    loss.backward()
    assert all(p.grad is not None for p in trainable)
    assert all(p.grad is None for p in transformer.parameters() if not p.requires_grad)
    with torch.no_grad():
        lora_v = r.velocity(z, torch.tensor([0.4]), z, z)
    assert not torch.allclose(lora_v, base_v)
    path = save_lora(transformer, tmp_path / "lora.safetensors")

    fresh, _ = tiny_flux(seed=5)
    fresh.load_state_dict(base_state)
    load_lora(fresh, path)
    with torch.no_grad():
        again = FluxRestorer(fresh, vae, *emb).velocity(z, torch.tensor([0.4]), z, z)
    assert torch.allclose(again, lora_v, atol=1e-5)


def test_load_flux_from_local_folders(tmp_path):
    transformer, vae = tiny_flux()
    emb = prompt_embeddings()
    z = torch.randn(1, 4, 8, 8)
    lora_scaled(transformer)
    expected = FluxRestorer(transformer, vae, *emb).velocity(z, torch.tensor([0.3]), z, z)
    save_lora(transformer, tmp_path / "restorer_lora.safetensors")
    transformer.unload_lora()
    transformer.save_pretrained(tmp_path / "transformer")
    vae.save_pretrained(tmp_path / "vae")
    save_file({"prompt_embeds": emb[0], "pooled_prompt_embeds": emb[1]}, str(tmp_path / "prompt.safetensors"))
    r = load_restorer(
        "flux",
        transformer=tmp_path / "transformer",
        vae=tmp_path / "vae",
        lora=tmp_path / "restorer_lora.safetensors",
        prompt=tmp_path / "prompt.safetensors",
    )
    r2 = load_flux(
        tmp_path / "transformer",
        tmp_path / "vae",
        tmp_path / "restorer_lora.safetensors",
        tmp_path / "prompt.safetensors",
        dtype=torch.float32,
    )
    with torch.no_grad():
        assert torch.allclose(r2.velocity(z, torch.tensor([0.3]), z, z), expected, atol=1e-5)
        assert r.velocity(z, torch.tensor([0.3]), z, z).shape == z.shape  # bfloat16 default


def test_without_weights_it_names_every_missing_file(tmp_path):
    with pytest.raises(InputError, match="not given: transformer, vae, lora, prompt"):
        load_flux()
    (tmp_path / "vae").mkdir()
    (tmp_path / "vae" / "config.json").write_text("{}")
    with pytest.raises(InputError) as info:
        load_flux(
            tmp_path / "transformer",
            tmp_path / "vae",
            tmp_path / "lora.safetensors",
            tmp_path / "p.safetensors",
        )
    msg = str(info.value)
    for name in (
        "transformer/config.json",
        "transformer/diffusion_pytorch_model.safetensors",
        "vae/diffusion_pytorch_model.safetensors",
        "lora.safetensors",
        "p.safetensors",
    ):
        assert name in msg
    assert "vae/config.json" not in msg
