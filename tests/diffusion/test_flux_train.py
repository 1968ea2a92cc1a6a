"""Flux LoRA training and the prompt-embedding file, on tiny random models saved to disk (no download)."""

import json

import numpy as np
import pytest
import torch
from safetensors.numpy import save_file as save_numpy
from safetensors.torch import load_file, save_file

from symdrive_core.cli import main
from symdrive_core.diffusion.flux import load_flux
from symdrive_core.diffusion.flux_train import CHECKPOINT, LORA, RECORD, FluxTrainConfig, train_flux_lora
from symdrive_core.diffusion.sampler import SamplerConfig, restore_image

from .helpers import prompt_embeddings, tiny_flux


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Tiny Flux transformer / VAE folders, a prompt file and a 2-pair file of 16 x 16 images."""
    root = tmp_path_factory.mktemp("flux")
    transformer, vae = tiny_flux()
    transformer.save_pretrained(root / "transformer")
    vae.save_pretrained(root / "vae")
    emb = prompt_embeddings()
    save_file({"prompt_embeds": emb[0], "pooled_prompt_embeds": emb[1]}, str(root / "prompt.safetensors"))
    rng = np.random.default_rng(0)
    base = (rng.random((2, 16, 16, 3)) * 255).astype(np.uint8)
    save_numpy(
        {
            "left": np.roll(base, 2, axis=2),
            "target": base,
            "right": np.roll(base, -2, axis=2),
            "offset": np.ones(2, np.float32),
            "frame": np.arange(2, dtype=np.int32),
        },
        str(root / "pairs.safetensors"),
    )
    return root


def tiny_cfg(**kw) -> FluxTrainConfig:
    base = dict(steps=50, batch=2, crop=16, rank=4, lr=1e-2, warmup=1, checkpoint_every=25, threads=1)
    return FluxTrainConfig(**{**base, **kw})


def train(files, out, cfg, **kw):
    return train_flux_lora(
        files / "pairs.safetensors",
        out,
        files / "transformer",
        files / "vae",
        files / "prompt.safetensors",
        cfg,
        progress=False,
        **kw,
    )


def test_defaults_are_the_papers():
    cfg = FluxTrainConfig()
    assert cfg.rank == 128 and cfg.gradient_checkpointing and cfg.mixed_precision == "auto"


def test_fifty_steps_lower_the_loss_on_a_fixed_batch(files, tmp_path):
    record = train(files, tmp_path, tiny_cfg(fixed_batch=True))
    losses = record["losses"]
    assert len(losses) == 50 and all(np.isfinite(losses))
    first, last = np.mean(losses[:5]), np.mean(losses[-5:])
    assert last < 0.8 * first, (first, last)  # measured: 1.39 -> 0.82
    assert record["mixed_precision"] == "no" and record["lora_parameters"] > 0
    assert (tmp_path / CHECKPOINT).is_file() and (tmp_path / LORA).is_file()
    assert json.loads((tmp_path / RECORD).read_text())["steps"] == 50


def test_command_trains_a_lora_that_backend_flux_loads_and_restores_with(files, tmp_path, capsys):
    out = tmp_path / "run"
    argv = [
        "train-restorer", str(files / "pairs.safetensors"), "--out", str(out), "--backend", "flux",
        "--flux-transformer", str(files / "transformer"), "--flux-vae", str(files / "vae"),
        "--prompt", str(files / "prompt.safetensors"), "--iters", "6", "--rank", "4", "--crop", "16",
        "--lr", "1e-2", "--warmup", "1", "--threads", "1", "--checkpoint-every", "3",
    ]  # fmt: skip
    assert main(argv) == 0
    assert json.loads(capsys.readouterr().out)["steps"] == 6
    lora = load_file(str(out / LORA))
    assert lora and all(k.startswith("transformer.") for k in lora)
    r = load_flux(files / "transformer", files / "vae", out / LORA, files / "prompt.safetensors", dtype=torch.float32)
    img = torch.rand(1, 3, 16, 16, generator=torch.Generator().manual_seed(3))
    restored = restore_image(r, img, img, img, SamplerConfig(steps=3, n_start=1))
    assert restored.shape == img.shape and bool(torch.isfinite(restored).all())
    assert float((restored - img).abs().mean()) > 1e-3
    # the adapter changes the prediction: the trained LoRA is in use, not an empty one
    z = torch.randn(1, 4, 8, 8)
    with torch.no_grad():
        v = r.velocity(z, torch.tensor([0.5]), z, z)
        r.transformer.disable_adapters()
        v0 = r.velocity(z, torch.tensor([0.5]), z, z)
    assert not torch.allclose(v, v0)


def test_resume_continues_from_the_checkpoint_step(files, tmp_path):
    whole = train(files, tmp_path / "whole", tiny_cfg(steps=4, checkpoint_every=2))
    train(files, tmp_path / "split", tiny_cfg(steps=2, checkpoint_every=2))
    resumed = train(files, tmp_path / "split", tiny_cfg(steps=4, checkpoint_every=2), resume=True)
    assert resumed["resumed_from"] == 2 and len(resumed["losses"]) == 4
    assert np.allclose(resumed["losses"], whole["losses"], rtol=1e-4, atol=1e-6)
    a, b = load_file(str(tmp_path / "whole" / LORA)), load_file(str(tmp_path / "split" / LORA))
    assert a.keys() == b.keys() and all(torch.allclose(a[k], b[k], atol=1e-5) for k in a)


def test_bad_inputs_exit_2_with_one_line_naming_file_and_field(files, tmp_path, capsys):
    common = ["--out", str(tmp_path / "o"), "--backend", "flux", "--flux-vae", str(files / "vae"),
              "--prompt", str(files / "prompt.safetensors")]  # fmt: skip
    cases = [
        ([str(files / "pairs.safetensors"), "--flux-transformer", str(tmp_path / "none"), *common],
         ["none/config.json", "--flux-transformer"]),
        ([str(files / "prompt.safetensors"), "--flux-transformer", str(files / "transformer"), *common],
         ["prompt.safetensors", "left"]),
        ([str(tmp_path / "missing.safetensors"), "--flux-transformer", str(files / "transformer"), *common],
         ["missing.safetensors", "PAIRS"]),
    ]  # fmt: skip
    for argv, words in cases:
        assert main(["train-restorer", *argv]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and all(w in err for w in words), err
    bad_prompt = tmp_path / "p.safetensors"
    save_file({"prompt_embeds": torch.zeros(3, 32)}, str(bad_prompt))
    argv = [str(files / "pairs.safetensors"), "--out", str(tmp_path / "o"), "--backend", "flux",
            "--flux-transformer", str(files / "transformer"), "--flux-vae", str(files / "vae"),
            "--prompt", str(bad_prompt)]  # fmt: skip
    assert main(["train-restorer", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert "p.safetensors" in err and "pooled_prompt_embeds" in err and len(err.splitlines()) == 1
    assert main(["train-restorer", str(files / "pairs.safetensors"), "--out", str(tmp_path), "--rank", "8"]) == 2
    assert "--rank" in capsys.readouterr().err


def tiny_text_encoders(root, words):
    """CLIP and T5 encoders from config (widths matching the tiny Flux) and word-level tokenizers."""
    from tokenizers import Tokenizer
    from tokenizers.models import WordLevel
    from tokenizers.pre_tokenizers import Whitespace
    from transformers import CLIPTextConfig, CLIPTextModel, PreTrainedTokenizerFast, T5Config, T5EncoderModel

    vocab = {"[PAD]": 0, "[UNK]": 1, "[EOS]": 2} | {w: i + 3 for i, w in enumerate(sorted(set(words)))}
    for folder, length in (("tokenizer", 8), ("tokenizer_2", 16)):
        tok = Tokenizer(WordLevel(vocab, unk_token="[UNK]"))
        tok.pre_tokenizer = Whitespace()
        fast = PreTrainedTokenizerFast(
            tokenizer_object=tok, pad_token="[PAD]", unk_token="[UNK]", eos_token="[EOS]", model_max_length=length
        )
        fast.save_pretrained(root / folder)
    torch.manual_seed(0)
    clip = CLIPTextModel(
        CLIPTextConfig(
            vocab_size=len(vocab), hidden_size=32, intermediate_size=37, num_hidden_layers=1,
            num_attention_heads=2, max_position_embeddings=8, projection_dim=32, bos_token_id=0, eos_token_id=2,
        )
    )  # fmt: skip
    clip.save_pretrained(root / "text_encoder")
    t5 = T5EncoderModel(
        T5Config(vocab_size=len(vocab), d_model=32, d_kv=8, d_ff=37, num_layers=1, num_heads=2)
    )
    t5.save_pretrained(root / "text_encoder_2")


def test_flux_prompt_writes_a_file_the_flux_backend_loads(files, tmp_path, capsys):
    text = "a street seen from a car"
    tiny_text_encoders(tmp_path / "enc", text.split())
    capsys.readouterr()
    out = tmp_path / "prompt.safetensors"
    argv = ["flux-prompt", "--text-encoders", str(tmp_path / "enc"), "--out", str(out), "--text", text,
            "--max-length", "16"]  # fmt: skip
    assert main(argv) == 0
    emb = load_file(str(out))
    assert emb["prompt_embeds"].shape == (16, 32) and emb["pooled_prompt_embeds"].shape == (32,)
    assert all(bool(torch.isfinite(v).all()) for v in emb.values())
    train(files, tmp_path / "lora", tiny_cfg(steps=1))
    r = load_flux(files / "transformer", files / "vae", tmp_path / "lora" / LORA, out, dtype=torch.float32)
    z = torch.randn(1, 4, 8, 8)
    with torch.no_grad():
        assert bool(torch.isfinite(r.velocity(z, torch.tensor([0.5]), z, z)).all())
    capsys.readouterr()
    assert main(["flux-prompt", "--text-encoders", str(tmp_path / "none"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "none" in err and "--text-encoders" in err and len(err.splitlines()) == 1
    # a truncated weights file, a config that is not JSON: one line naming the folder
    weights = next((tmp_path / "enc" / "text_encoder_2").glob("*.safetensors"))
    weights.write_bytes(weights.read_bytes()[:100])
    assert main(["flux-prompt", "--text-encoders", str(tmp_path / "enc"), "--out", str(tmp_path / "p2")]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]  # after transformers' own loading bar of the CLIP
    assert err.startswith("symdrive flux-prompt: error: ") and "text_encoder_2: cannot load the T5 text encoder" in err
    (tmp_path / "enc" / "text_encoder" / "config.json").write_text("{not json")
    assert main(["flux-prompt", "--text-encoders", str(tmp_path / "enc"), "--out", str(tmp_path / "p2")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("symdrive flux-prompt: error: ") and "text_encoder: cannot load the CLIP text encoder" in err
    assert not (tmp_path / "p2").exists()
