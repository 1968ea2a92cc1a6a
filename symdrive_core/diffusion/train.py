"""``symdrive train-restorer``: flow-matching training of the built-in restorer on pairs.

Adam with a short warm-up and a cosine decay, an exponential moving average of the weights
(the EMA is what ships: it samples more smoothly than the last iterate), checkpoints every
``checkpoint_every`` steps holding model, EMA and Adam state. Every batch and noise draw comes
from a generator seeded by ``(seed, step)``, so a run resumed from a checkpoint continues
exactly as an uninterrupted one would.

Noise levels are drawn uniformly on ``[0, t_max]`` with a ``full_fraction`` share on all of
``[0, 1]``: the default sampler starts at ``N_start = 10`` of 50 steps, i.e. ``t = 0.8``, and never
evaluates the model above it, while RePaint or ``N_start = 0`` still get some coverage. The
squared velocity error is weighted per sample by ``UNet.loss_weight`` (unit scale for the
network's correction under the ``skip`` output).

When the pairs file has degraded starts (cycle reconstructions), a ``degraded_fraction`` share
of each batch starts its noisy state from one of them and learns the velocity back to the
recorded image (``flow.flow_loss``'s ``x_start``). ``init`` continues from trained weights.

``guide`` trains the network with the geometry-guided warp and its mask as a fourth condition
(pairs made with ``warps``); from unguided ``init`` weights the new inputs start at zero
(:func:`.unet.with_guide`), so fine-tuning starts from exactly the network it extends.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict
from pathlib import Path

import torch

from ..errors import InputError
from ..io.atomic import atomic_path, write_text_atomic
from . import flow
from .config import GUIDE_CHANNELS, TrainConfig
from .data import PairFamily, file_sha256
from .models import BuiltinRestorer, load_builtin, save_builtin
from .unet import UNet, with_guide

CHECKPOINT = "checkpoint.safetensors"
WEIGHTS = "restorer.safetensors"
RECORD = "restorer.json"


def learning_rate(cfg: TrainConfig, step: int) -> float:
    if step < cfg.warmup:
        return cfg.lr * (step + 1) / cfg.warmup
    u = (step - cfg.warmup) / max(cfg.steps - cfg.warmup, 1)
    return cfg.lr * (0.1 + 0.9 * 0.5 * (1.0 + math.cos(math.pi * min(u, 1.0))))


def step_generator(seed: int, step: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed * 1_000_003 + step)


@torch.no_grad()
def ema_update(ema: UNet, net: UNet, decay: float) -> None:
    for e, p in zip(ema.parameters(), net.parameters()):
        e.lerp_(p, 1.0 - decay)
    for e, b in zip(ema.buffers(), net.buffers()):
        e.copy_(b)


def save_checkpoint(
    path: Path, net: UNet, ema: UNet, opt: torch.optim.Adam, step: int, losses: list[float], cfg: TrainConfig
) -> None:
    from safetensors.torch import save_file

    tensors = {f"model.{k}": v for k, v in net.state_dict().items()}
    tensors |= {f"ema.{k}": v for k, v in ema.state_dict().items()}
    tensors |= optimizer_tensors(opt)
    meta = {"step": str(step), "losses": json.dumps(losses), "config": json.dumps(asdict(cfg))}
    with atomic_path(path) as tmp:
        save_file({k: v.detach().contiguous() for k, v in tensors.items()}, str(tmp), metadata=meta)


def load_checkpoint(path: Path, net: UNet, ema: UNet, opt: torch.optim.Adam) -> tuple[int, list[float]]:
    from ..io.tensor_file import read_tensor_file

    t, meta = read_tensor_file(path, "a training checkpoint")
    try:
        net.load_state_dict({k[6:]: v for k, v in t.items() if k.startswith("model.")})
        ema.load_state_dict({k[4:]: v for k, v in t.items() if k.startswith("ema.")})
        load_optimizer_tensors(opt, t)
        return int(meta["step"]), json.loads(meta["losses"])
    except (RuntimeError, KeyError, ValueError) as exc:
        raise InputError(path, "a checkpoint of another network (its --width, --guide or --output differ from this "
                               f"run's): {str(exc).splitlines()[0]}") from None


def optimizer_tensors(opt: torch.optim.Optimizer) -> dict[str, torch.Tensor]:
    """Adam's per-parameter state as flat named tensors (``adam.<i>.<key>``): safetensors
    checkpoints hold tensors only, and resuming needs the moments to continue exactly."""
    out: dict[str, torch.Tensor] = {}
    for i, st in opt.state_dict()["state"].items():
        out |= {f"adam.{i}.{k}": v.reshape(-1) if k == "step" else v for k, v in st.items()}
    return out


def load_optimizer_tensors(opt: torch.optim.Optimizer, t: dict[str, torch.Tensor]) -> None:
    """The inverse of :func:`optimizer_tensors`, into ``opt`` (parameters without state stay fresh)."""
    state = opt.state_dict()
    for i in state["param_groups"][0]["params"]:
        if f"adam.{i}.step" in t:
            state["state"][i] = {"step": t[f"adam.{i}.step"].reshape(()), "exp_avg": t[f"adam.{i}.exp_avg"],
                                 "exp_avg_sq": t[f"adam.{i}.exp_avg_sq"]}
    opt.load_state_dict(state)


def data_record(data: PairFamily) -> dict:
    """What the weights were trained on: each pairs file's name, SHA-256, pair counts and the
    settings make-pairs recorded; for several files, a list of those under ``files`` and the totals."""
    def one(s) -> dict:
        return {"file": s.path.name, "sha256": file_sha256(s.path), "pairs": len(s),
                "sensor_pairs": int(s.from_sensor.sum()),
                **{k: json.loads(s.metadata[k]) for k in ("frames", "offsets", "cycle_offsets", "drive")
                   if k in s.metadata}}

    if len(data.sets) == 1:
        return one(data.sets[0])
    return {"files": [one(s) for s in data.sets], "pairs": len(data), "sensor_pairs": int(data.from_sensor.sum())}


def train_restorer(
    pairs: str | Path | list,
    out: str | Path,
    cfg: TrainConfig | None = None,
    *,
    resume: bool = False,
    command: str | None = None,
    progress: bool = True,
) -> dict:
    """Train on ``pairs`` (a pairs file, or a list of them: a family of streets drawn as one set);
    write ``out/restorer.safetensors`` (EMA, float16), ``out/restorer.json`` (config, command, data
    hashes, steps, final loss, seconds) and ``out/checkpoint.safetensors``."""
    from tqdm import tqdm

    cfg = cfg or TrainConfig()
    out = Path(out)
    torch.set_num_threads(cfg.threads)
    files = [Path(p) for p in ([pairs] if isinstance(pairs, (str, Path)) else pairs)]
    data = PairFamily(files, cfg.holdout_frames, warps=cfg.guide)
    if not len(data):
        raise InputError(files[0], "no pairs left to train on once the held-out frames are left out")
    if cfg.guide and not data.has_warps:
        raise InputError(files[0], "training with the guide needs pairs with warps (`symdrive make-pairs --warps`)")
    torch.manual_seed(cfg.seed)
    net = UNet(cfg.unet())
    if cfg.init:
        start_from = load_builtin(cfg.init).net
        if cfg.guide and not start_from.config.guide_channels:
            start_from = with_guide(start_from, GUIDE_CHANNELS)
        if start_from.config != net.config:
            raise InputError(cfg.init, f"its UNet {start_from.config} is not the one configured ({net.config})")
        net.load_state_dict(start_from.state_dict())
    ema = UNet(cfg.unet())
    ema.load_state_dict(net.state_dict())
    ema.requires_grad_(False)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    start, losses = 0, []
    ckpt = out / CHECKPOINT
    if resume and ckpt.exists():
        start, losses = load_checkpoint(ckpt, net, ema, opt)
    model = BuiltinRestorer(net).train()
    done = start
    t0 = time.perf_counter()
    bar = tqdm(
        range(start, cfg.steps),
        desc="train-restorer",
        unit="step",
        disable=not progress,
        initial=start,
        total=cfg.steps,
    )
    for step in bar:
        g = step_generator(cfg.seed, step)
        left, target, right, start_image, guide = data.batch(cfg.batch, cfg.crop, g, cfg.degraded_fraction)
        lat = model.latent
        zl, zr = lat.encode(left), lat.encode(right)
        zg = model.encode_guide(guide) if cfg.guide else None
        loss = flow.flow_loss(
            lambda z, t, zl=zl, zr=zr, zg=zg: model.velocity(z, t, zl, zr, zg),
            lat.encode(target),
            g,
            t_max=cfg.t_max,
            full_fraction=cfg.full_fraction,
            weight=net.loss_weight,
            x_start=lat.encode(start_image) if data.has_degraded else None,
            start_t_min=cfg.start_t_min,
        )
        for group in opt.param_groups:
            group["lr"] = learning_rate(cfg, step)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        ema_update(ema, net, cfg.ema)
        losses.append(round(loss.item(), 6))
        if (step + 1) % 10 == 0:
            bar.set_postfix(loss=f"{sum(losses[-100:]) / len(losses[-100:]):.4f}")
        done = step + 1
        out_of_time = cfg.max_seconds is not None and time.perf_counter() - t0 >= cfg.max_seconds
        if done % cfg.checkpoint_every == 0 or done == cfg.steps or out_of_time:
            save_checkpoint(ckpt, net, ema, opt, done, losses, cfg)
        if out_of_time:
            break
    bar.close()
    tail = losses[-100:]
    record = {
        "config": {**asdict(cfg), "unet": cfg.unet().to_json()},
        "command": command,
        "data": data_record(data),
        "steps": done,
        "resumed_from": start,
        "final_loss": round(sum(tail) / max(len(tail), 1), 6),
        "seconds": round(time.perf_counter() - t0, 1),
        "loss_every_100": [
            round(sum(losses[i : i + 100]) / len(losses[i : i + 100]), 5) for i in range(0, len(losses), 100)
        ],
    }
    save_builtin(
        out / WEIGHTS, ema, {k: record[k] for k in ("command", "data", "steps", "final_loss")}, half=True
    )
    write_text_atomic(out / RECORD, json.dumps(record, indent=1) + "\n")
    return record
