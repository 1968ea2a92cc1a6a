"""A few real-size Flux LoRA training steps on a GPU: time per step and peak memory.

    python scripts/train_flux_lora_gpu.py --flux-transformer FLUX.1-dev/transformer \\
        --flux-vae FLUX.1-dev/vae [--prompt prompt.safetensors] [--sizes 512x512,1024x576] [--rank 128]

or, without the weights, the same architecture with random weights (FLUX.1-dev's config; the
memory and time are the same, the loss is meaningless):

    python scripts/train_flux_lora_gpu.py --random-weights

Each size trains ``--steps`` steps (batch 1, bf16, gradient checkpointing) through
``symdrive train-restorer --backend flux``'s code on one synthetic pair of that size, and the
script prints one JSON line per size: seconds per step (after the first, which includes
warm-up), peak allocated GPU memory, LoRA parameter count. Without a CUDA GPU it says so and
exits 0.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's symdrive_core


def _sizes(text: str) -> list[tuple[int, int]]:
    out = []
    for item in text.split(","):
        w, h = item.lower().split("x")
        out.append((int(w), int(h)))
    return out


def random_flux(root: Path, tiny: bool) -> tuple[Path, Path, Path]:
    """FLUX.1-dev's transformer and VAE configs with random weights, saved as diffusers folders."""
    import torch
    from diffusers import AutoencoderKL, FluxTransformer2DModel
    from safetensors.torch import save_file

    kw = {}
    vae_kw = dict(
        in_channels=3, out_channels=3, latent_channels=16, scaling_factor=0.3611, shift_factor=0.1159,
        use_quant_conv=False, use_post_quant_conv=False,
        down_block_types=("DownEncoderBlock2D",) * 4, up_block_types=("UpDecoderBlock2D",) * 4,
        block_out_channels=(128, 256, 512, 512), layers_per_block=2,
    )  # fmt: skip
    text_dim, pooled_dim = 4096, 768
    if tiny:  # a smoke test of this script on the CPU
        kw = dict(num_layers=1, num_single_layers=1, attention_head_dim=16, num_attention_heads=2,
                  joint_attention_dim=32, pooled_projection_dim=32, axes_dims_rope=(4, 6, 6))  # fmt: skip
        vae_kw |= dict(block_out_channels=(8, 8, 16, 16), layers_per_block=1, norm_num_groups=4)
        text_dim, pooled_dim = 32, 32
    with torch.device("cuda" if torch.cuda.is_available() else "cpu"):
        net = FluxTransformer2DModel(guidance_embeds=True, **kw).to(torch.bfloat16)
    net.save_pretrained(root / "transformer")
    del net
    AutoencoderKL(**vae_kw).to(torch.bfloat16).save_pretrained(root / "vae")
    g = torch.Generator().manual_seed(0)
    save_file(
        {"prompt_embeds": torch.randn(512, text_dim, generator=g), "pooled_prompt_embeds": torch.randn(pooled_dim, generator=g)},
        str(root / "prompt.safetensors"),
    )
    return root / "transformer", root / "vae", root / "prompt.safetensors"


def synthetic_pairs(path: Path, width: int, height: int) -> Path:
    import numpy as np
    from safetensors.numpy import save_file

    rng = np.random.default_rng(0)
    img = (rng.random((1, height, width, 3)) * 255).astype(np.uint8)
    save_file({"left": np.roll(img, 8, axis=2), "target": img, "right": np.roll(img, -8, axis=2)}, str(path))
    return path


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--flux-transformer", type=Path)
    p.add_argument("--flux-vae", type=Path)
    p.add_argument("--prompt", type=Path, help="from `symdrive flux-prompt` (default: random embeddings)")
    p.add_argument("--random-weights", action="store_true", help="FLUX.1-dev's architecture, random weights")
    p.add_argument("--sizes", type=_sizes, default=_sizes("512x512,1024x576"), help="WxH,... (default 512x512,1024x576)")
    p.add_argument("--rank", type=int, default=128)
    p.add_argument("--steps", type=int, default=4)
    p.add_argument("--no-gradient-checkpointing", action="store_true")
    p.add_argument("--tiny-cpu-smoke", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args(argv)

    import torch

    if not torch.cuda.is_available() and not args.tiny_cpu_smoke:
        print("train_flux_lora_gpu.py needs a CUDA GPU and none is present: nothing was run "
              "(the CPU tests cover the training code on a tiny model: tests/diffusion/test_flux_train.py)")
        return 0
    from symdrive_core.diffusion.flux_train import FluxTrainConfig, train_flux_lora

    with tempfile.TemporaryDirectory(prefix="flux_gpu_") as tmp:
        tmp = Path(tmp)
        if args.random_weights or args.tiny_cpu_smoke:
            transformer, vae, prompt = random_flux(tmp, tiny=args.tiny_cpu_smoke)
        else:
            if args.flux_transformer is None or args.flux_vae is None:
                p.error("give --flux-transformer and --flux-vae (local FLUX.1-dev folders), or --random-weights")
            transformer, vae = args.flux_transformer, args.flux_vae
            prompt = args.prompt
            if prompt is None:
                from safetensors.torch import save_file

                g = torch.Generator().manual_seed(0)
                prompt = tmp / "prompt.safetensors"
                save_file({"prompt_embeds": torch.randn(512, 4096, generator=g),
                           "pooled_prompt_embeds": torch.randn(768, generator=g)}, str(prompt))  # fmt: skip
        device = torch.cuda.get_device_name(0) if torch.cuda.is_available() else "cpu"
        for width, height in args.sizes:
            pairs = synthetic_pairs(tmp / f"pairs_{width}x{height}.safetensors", width, height)
            cfg = FluxTrainConfig(steps=args.steps, batch=1, crop=max(width, height), rank=args.rank,
                                  checkpoint_every=10**9, gradient_checkpointing=not args.no_gradient_checkpointing)  # fmt: skip
            times = []
            t_last = [time.perf_counter()]

            def tick(step, loss, times=times, t_last=t_last):
                if torch.cuda.is_available():
                    torch.cuda.synchronize()
                now = time.perf_counter()
                times.append(now - t_last[0])
                t_last[0] = now

            if torch.cuda.is_available():
                torch.cuda.empty_cache()
            rec = train_flux_lora(pairs, tmp / f"out_{width}x{height}", transformer, vae, prompt, cfg,
                                  progress=False, loss_callback=tick)  # fmt: skip
            steady = times[1:] or times
            print(json.dumps({
                "device": device, "size": f"{width}x{height}", "rank": args.rank,
                "gradient_checkpointing": cfg.gradient_checkpointing, "steps": args.steps,
                "seconds_first_step": round(times[0], 2), "seconds_per_step": round(sum(steady) / len(steady), 3),
                "peak_gpu_memory_gib": rec["peak_gpu_memory_gib"], "lora_parameters": rec["lora_parameters"],
                "mixed_precision": rec["mixed_precision"], "loss": rec["losses"],
            }), flush=True)  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
