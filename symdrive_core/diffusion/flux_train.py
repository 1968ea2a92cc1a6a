"""``symdrive train-restorer --backend flux``: a LoRA on Flux.1-dev over the symmetric pairs.

The paper's recipe: a rank-128 LoRA on the Flux transformer (base weights frozen), trained with
the rectified-flow loss on ``(I_-d, I_d) -> I_0`` pairs, the two side views entering as
in-context tokens exactly as :class:`.flux.FluxRestorer` samples them (the same ``velocity``
call is trained). Noise levels are drawn uniformly and mapped through Flux's resolution shift
``mu``, so training sees the levels the sampler visits. The pairs file is the one the built-in
model trains on (:class:`.data.PairSet`: random crops, mirror augmentation, degraded starts).

Runs on one CPU process (float32, for tests) or on one or many GPUs through ``accelerate``
(``accelerate launch -m symdrive_core.cli train-restorer --backend flux ...``): bf16 autocast,
frozen base weights in bf16 and the LoRA weights in float32, gradient checkpointing.
A checkpoint (``OUT/flux_checkpoint.safetensors``: the LoRA from peft's
``get_peft_model_state_dict``, the AdamW state, step and losses) and the LoRA that
``--backend flux`` loads (``OUT/restorer_lora.safetensors``) are written every
``checkpoint_every`` steps; ``resume`` continues from the checkpoint. Every batch and noise draw
comes from a generator seeded by ``(seed, process, step)``, so a resumed run repeats the draws
an uninterrupted one makes.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

import torch

from ..errors import InputError
from ..io.atomic import atomic_path, write_text_atomic
from . import flow
from .config import FluxTrainConfig
from .flux import FluxRestorer, add_lora, save_lora
from .pretrained import load_pretrained
from .train import load_optimizer_tensors, optimizer_tensors

CHECKPOINT = "flux_checkpoint.safetensors"
LORA = "restorer_lora.safetensors"
RECORD = "flux_lora.json"


def learning_rate(cfg: FluxTrainConfig, step: int) -> float:
    return cfg.lr * min(1.0, (step + 1) / max(cfg.warmup, 1))


def step_generator(seed: int, process: int, step: int) -> torch.Generator:
    return torch.Generator().manual_seed((seed * 1_000_003 + step) * 1009 + process)


def _check_folder(folder, option: str) -> Path:
    if folder is None:
        raise InputError(option, "required with --backend flux (a diffusers folder from FLUX.1-dev)", option)
    folder = Path(folder)
    if not (folder / "config.json").is_file():
        raise InputError(folder / "config.json", "not found (expected a diffusers model folder)", option)
    if not any(folder.glob("diffusion_pytorch_model*.safetensors")):
        raise InputError(
            folder / "diffusion_pytorch_model.safetensors", "not found (nor its shards + index)", option
        )
    return folder


def read_prompt(path, text_dim: int | None = None, pooled_dim: int | None = None):
    """``(prompt_embeds [L, D], pooled_prompt_embeds [P])`` from the file ``flux-prompt`` writes."""
    from ..io.tensor_file import read_tensor_file

    if path is None:
        raise InputError("--prompt", "required with --backend flux (write it with `symdrive flux-prompt`)", "--prompt")
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "prompt-embedding file not found (write it with `symdrive flux-prompt`)", "--prompt")
    emb, _ = read_tensor_file(path, "a prompt-embedding file", field="--prompt")
    for key in ("prompt_embeds", "pooled_prompt_embeds"):
        if key not in emb:
            raise InputError(path, "no such tensor", key)
    text, pooled = emb["prompt_embeds"], emb["pooled_prompt_embeds"]
    text = text.reshape(-1, text.shape[-1])
    pooled = pooled.reshape(-1)
    if text_dim is not None and text.shape[-1] != text_dim:
        raise InputError(path, f"width {text.shape[-1]}, the transformer expects {text_dim}", "prompt_embeds")
    if pooled_dim is not None and pooled.shape[-1] != pooled_dim:
        raise InputError(path, f"width {pooled.shape[-1]}, the transformer expects {pooled_dim}", "pooled_prompt_embeds")
    return text, pooled


def _open_pairs(path):
    from safetensors import safe_open

    from .data import PairSet

    path = Path(path)
    if not path.is_file():
        raise InputError(path, "pairs file not found (write one with `symdrive make-pairs`)", "PAIRS")
    try:
        with safe_open(str(path), "np") as f:
            keys = set(f.keys())
    except Exception as exc:  # noqa: BLE001
        raise InputError(path, f"not a safetensors pairs file ({type(exc).__name__})", "PAIRS") from exc
    for key in ("left", "target", "right"):
        if key not in keys:
            raise InputError(path, "not a pairs file: no such tensor", key)
    return PairSet(path)


def _lora_parameters(transformer) -> list[tuple[str, torch.nn.Parameter]]:
    return [(n, p) for n, p in transformer.named_parameters() if p.requires_grad]


def save_checkpoint(path: Path, transformer, opt, step: int, losses: list[float], cfg: FluxTrainConfig) -> None:
    from peft.utils import get_peft_model_state_dict
    from safetensors.torch import save_file

    tensors = {f"lora.{k}": v for k, v in get_peft_model_state_dict(transformer).items()}
    tensors |= optimizer_tensors(opt)
    meta = {"step": str(step), "losses": json.dumps(losses), "config": json.dumps(asdict(cfg))}
    with atomic_path(path) as tmp:
        save_file({k: v.detach().float().contiguous().cpu() for k, v in tensors.items()}, str(tmp), metadata=meta)


def load_checkpoint(path: Path, transformer, opt, cfg: FluxTrainConfig) -> tuple[int, list[float]]:
    from peft.utils import set_peft_model_state_dict
    from safetensors import safe_open

    try:
        with safe_open(str(path), "pt") as f:
            meta = f.metadata() or {}
            t = {k: f.get_tensor(k) for k in f.keys()}  # noqa: SIM118 (not a dict)
    except Exception as exc:  # noqa: BLE001
        raise InputError(path, f"unreadable checkpoint ({type(exc).__name__})") from exc
    if "step" not in meta:
        raise InputError(path, "not a Flux LoRA checkpoint: no step in its metadata", "step")
    saved = json.loads(meta.get("config", "{}"))
    for key in ("rank", "targets"):
        if key in saved and (list(saved[key]) if key == "targets" else saved[key]) != (
            list(getattr(cfg, key)) if key == "targets" else getattr(cfg, key)
        ):
            raise InputError(path, f"checkpoint has {key} {saved[key]}, this run {getattr(cfg, key)}", key)
    state = {k[5:]: v for k, v in t.items() if k.startswith("lora.")}
    result = set_peft_model_state_dict(transformer, state)
    if getattr(result, "unexpected_keys", None):
        raise InputError(path, f"LoRA keys the transformer lacks: {result.unexpected_keys[:3]}", "lora")
    load_optimizer_tensors(opt, t)
    return int(meta["step"]), json.loads(meta["losses"])


def flux_flow_loss(restorer: FluxRestorer, left, target, right, start, generator, cfg: FluxTrainConfig, has_degraded):
    """Rectified-flow loss on latents: ``z_t = (1 - t) x + t eps``, target ``eps - x`` (or the
    repair velocity for a degraded start), ``t`` uniform then shifted by Flux's ``mu``."""
    lat = restorer.latent
    zl, zr, x0 = lat.encode(left), lat.encode(right), lat.encode(target)
    xs = lat.encode(start) if has_degraded else x0
    b = x0.shape[0]
    u = flow.training_times(b, generator, cfg.t_max, 0.0)
    t = flow.time_shift(u.double(), restorer.time_shift(x0.shape)).float()
    eps = torch.randn(x0.shape, generator=generator)
    repair = (xs != x0).flatten(1).any(1)
    t = torch.where(repair, cfg.start_t_min + (1.0 - cfg.start_t_min) * t, t).clamp(1e-4, 1.0)
    z_t = flow.noised(xs, eps, t)
    target_v = flow.start_velocity_target(x0, xs, eps, t)
    dev = next(restorer.transformer.parameters()).device
    v = restorer.velocity(z_t.to(dev), t.to(dev), zl.to(dev), zr.to(dev))
    return ((v.float() - target_v.to(dev)) ** 2).mean()


def _trim(images, multiple: int):
    h, w = images[0].shape[-2:]
    h, w = h - h % multiple, w - w % multiple
    return [x[..., :h, :w] for x in images]


def train_flux_lora(
    pairs,
    out,
    transformer_dir,
    vae_dir,
    prompt,
    cfg: FluxTrainConfig | None = None,
    *,
    resume: bool = False,
    command: str | None = None,
    progress: bool = True,
    loss_callback=None,
) -> dict:
    """Train the LoRA; write ``OUT/restorer_lora.safetensors`` (what ``--backend flux --flux-lora``
    loads), ``OUT/flux_checkpoint.safetensors`` and ``OUT/flux_lora.json`` (config, command, data
    hash, losses, seconds, peak memory). ``transformer_dir`` / ``vae_dir`` are diffusers folders."""
    cfg = cfg or FluxTrainConfig()
    transformer_dir = _check_folder(transformer_dir, "--flux-transformer")
    vae_dir = _check_folder(vae_dir, "--flux-vae")
    data = _open_pairs(pairs)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(out, "exists and is not a folder", "--out")

    from accelerate import Accelerator
    from diffusers import AutoencoderKL, FluxTransformer2DModel
    from tqdm import tqdm

    from .data import file_sha256

    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    cuda = torch.cuda.is_available()
    precision = cfg.mixed_precision if cfg.mixed_precision != "auto" else ("bf16" if cuda else "no")
    acc = Accelerator(mixed_precision=precision, gradient_accumulation_steps=cfg.grad_accum, cpu=not cuda)
    base_dtype = {"bf16": torch.bfloat16, "fp16": torch.float16}.get(precision, torch.float32)
    net = load_pretrained(FluxTransformer2DModel, transformer_dir, "the FLUX.1-dev transformer", torch_dtype=base_dtype)
    ae = load_pretrained(AutoencoderKL, vae_dir, "the FLUX.1-dev VAE", torch_dtype=base_dtype)
    text, pooled = read_prompt(prompt, net.config.joint_attention_dim, net.config.pooled_projection_dim)
    torch.manual_seed(cfg.seed)
    add_lora(net, rank=cfg.rank, alpha=cfg.alpha, targets=cfg.targets)
    for p in net.parameters():  # the adapter trains in float32 whatever the base weights are
        if p.requires_grad:
            p.data = p.data.float()
    if cfg.gradient_checkpointing and getattr(net, "_supports_gradient_checkpointing", False):
        net.enable_gradient_checkpointing()
    named = _lora_parameters(net)
    if not named:
        raise InputError(transformer_dir, f"no module matches the LoRA targets {list(cfg.targets)}", "--targets")
    opt = torch.optim.AdamW([p for _, p in named], lr=cfg.lr, weight_decay=0.0)
    net.to(acc.device)
    ae.to(acc.device)
    net.train()
    model, opt = acc.prepare(net, opt)
    restorer = FluxRestorer(net, ae, text, pooled, guidance=cfg.guidance, model=model)
    factor = restorer.latent.factor * 2  # whole 2x2 patches of latent cells

    ckpt = out / CHECKPOINT
    start, losses = 0, []
    if resume and ckpt.exists():
        start, losses = load_checkpoint(ckpt, acc.unwrap_model(model), opt, cfg)
    out.mkdir(parents=True, exist_ok=True)
    if cuda:
        torch.cuda.reset_peak_memory_stats()
    t0 = time.perf_counter()
    bar = tqdm(
        range(start, cfg.steps),
        desc="train-restorer (flux)",
        unit="step",
        disable=not progress or not acc.is_local_main_process,
        initial=start,
        total=cfg.steps,
    )
    for step in bar:
        loss_sum = 0.0
        for micro in range(cfg.grad_accum):
            g = step_generator(cfg.seed, acc.process_index, 0 if cfg.fixed_batch else step * cfg.grad_accum + micro)
            views = data.batch(cfg.batch, cfg.crop, g, cfg.degraded_fraction)
            left, target, right, start_image = _trim(list(views[:4]), factor)
            if min(target.shape[-2:]) < factor:
                raise InputError(data.path, f"images smaller than {factor} px cannot be packed", "target")
            with acc.accumulate(model):
                with acc.autocast():
                    loss = flux_flow_loss(restorer, left, target, right, start_image, g, cfg, data.has_degraded)
                acc.backward(loss)
                if acc.sync_gradients and cfg.max_grad_norm > 0:
                    acc.clip_grad_norm_([p for _, p in named], cfg.max_grad_norm)
                for group in opt.param_groups:
                    group["lr"] = learning_rate(cfg, step)
                opt.step()
                opt.zero_grad(set_to_none=True)
            loss_sum += loss.detach().float()
        mean = acc.gather(loss_sum.reshape(1).to(acc.device) / cfg.grad_accum).mean().item()
        losses.append(round(mean, 6))
        if loss_callback is not None:
            loss_callback(step, mean)
        bar.set_postfix(loss=f"{sum(losses[-20:]) / len(losses[-20:]):.4f}")
        if (step + 1) % cfg.checkpoint_every == 0 or step + 1 == cfg.steps:
            acc.wait_for_everyone()
            if acc.is_main_process:
                inner = acc.unwrap_model(model)
                save_checkpoint(ckpt, inner, opt, step + 1, losses, cfg)
                save_lora(inner, out / LORA)
    bar.close()
    seconds = time.perf_counter() - t0
    done = max(cfg.steps - start, 0)
    record = {
        "backend": "flux",
        "config": asdict(cfg),
        "command": command,
        "transformer": str(transformer_dir),
        "vae": str(vae_dir),
        "prompt": str(prompt),
        "data": {"file": Path(pairs).name, "sha256": file_sha256(pairs), "pairs": len(data)},
        "steps": cfg.steps,
        "resumed_from": start,
        "processes": acc.num_processes,
        "mixed_precision": precision,
        "device": str(acc.device),
        "lora_parameters": sum(p.numel() for _, p in named),
        "final_loss": round(sum(losses[-20:]) / max(len(losses[-20:]), 1), 6),
        "seconds": round(seconds, 1),
        "seconds_per_step": round(seconds / done, 4) if done else None,
        "peak_gpu_memory_gib": round(torch.cuda.max_memory_allocated() / 2**30, 2) if cuda else None,
        "losses": losses,
    }
    if acc.is_main_process:
        if not (out / LORA).exists():  # resumed at or past the last step
            save_lora(acc.unwrap_model(model), out / LORA)
        write_text_atomic(out / RECORD, json.dumps(record, indent=1) + "\n")
    acc.end_training()
    return record
