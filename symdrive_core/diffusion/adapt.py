"""The restorer adapts to the drive it restores.

The shipped weights were trained on one synthetic street; on a drive they have not seen they
barely change the raw render. The paper's remedy is to train on the drive's own pairs: renders of
its reconstruction symmetric around each recorded training frame, the recorded image the target,
with the degraded starts and warps the shipped guided restorer learnt from
(:func:`.data.make_pairs`). Here that is a short fine-tune from the shipped weights
(:func:`.train.train_restorer`) within the budget of an :class:`AdaptConfig`.

Weights record the drive they were trained on (:func:`drive_identity`, the content of its recorded
frames and of its reconstruction; ``make-pairs`` writes it, training passes it on), so the planner
adapts only when the weights were trained on another drive. The held-out frames never take part.

Nothing here imports torch at module level: the planner and ``StageOptions`` read this module.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

from . import defaults

PAIRS = "pairs.safetensors"


@dataclass(frozen=True)
class AdaptConfig:
    """Budget and recipe of one adaptation (``StageOptions.adapt``). ``max_seconds`` bounds the
    whole adaptation: training stops when making the pairs and the steps so far have used it."""

    iters: int = 400
    max_seconds: float | None = 600.0
    offsets: tuple[float, ...] = (0.5, 1.0, 1.5)  # the pairs' symmetric distances d (metres)
    cycle_offsets: tuple[float, ...] = (-1.5, 1.5)  # the cycle reconstructions of the degraded starts
    cycle_iters: int = 300
    lr: float = 1e-4  # a quarter of training from scratch: it starts from trained weights
    warmup: int = 20
    degraded_fraction: float = 0.75  # as the shipped guided restorer was trained
    seed: int = 0
    threads: int = 1
    # pairs whose target a rig's second camera recorded at the training frames (:mod:`.sensor_pairs`)
    sensor_pairs: bool = True
    # every this many training frames one is left out of training, to fit the restorer's strength
    # on (:mod:`.strength`); fewer than two such groups of frames: no fit, the full strength
    validation_every: int = 8


def validation_frames(frames: list[int], every: int) -> list[int]:
    """The frames the strength is fitted on: one in ``every``, from the middle of each group."""
    return list(frames[every // 2 :: every]) if every > 0 and len(frames) >= 2 * every else []


def shipped_weights(guided: bool) -> Path:
    """The weights an adaptation starts from: the guided restorer where it ships, else the default."""
    guided_weights = defaults.GUIDED_WEIGHTS
    return guided_weights if guided and guided_weights.exists() else defaults.DEFAULT_WEIGHTS


def drive_identity(manifest, reconstruction: str | Path) -> dict:
    """``{"scene", "identity"}``: the scene's name, and a hash of what training pairs are made from
    (the ground-truth camera's frames: size, intrinsics, poses, recorded image and depth bytes;
    the images a rig's second camera recorded beside it; and the reconstruction's bytes). File
    names play no part: a copied package is the same drive."""
    from ..scene.ground_truth import truth_camera
    from .sensor_pairs import sensor_views

    cam = truth_camera(manifest)
    geometry = [cam.width, cam.height, [[cf.K.tolist(), cf.camera_to_world.tolist()] for cf in cam.frames]]
    h = hashlib.sha256(json.dumps(geometry).encode())
    paths = [manifest.resolve(rel) if rel else None for cf in cam.frames for rel in (cf.image, cf.depth)]
    paths += [manifest.resolve(v.image) for v in sensor_views(manifest, cam.name, range(len(cam.frames)))]
    for path in [*paths, Path(reconstruction)]:
        if path is None or not path.is_file():
            h.update(b"\0missing")
            continue
        with open(path, "rb") as f:
            h.update(hashlib.file_digest(f, "sha256").digest())
    return {"scene": manifest.name, "identity": h.hexdigest()[:16]}


def weights_meta(weights: str | Path) -> dict:
    """What a weights file records beside its network (``meta``: data, drive, steps, strength)."""
    from safetensors import safe_open

    with safe_open(str(weights), "np") as f:
        return json.loads((f.metadata() or {}).get("meta", "{}"))


def trained_drives(weights: str | Path) -> list[dict]:
    """The drives ``weights`` were trained on, from their metadata: the one of a single pairs file,
    or each of a family's files (``[]``: not recorded)."""
    from safetensors import SafetensorError

    try:
        meta = weights_meta(weights)
    except (OSError, SafetensorError, json.JSONDecodeError):
        return []
    data = meta.get("data", {}) if isinstance(meta, dict) else {}
    records = data.get("files", [data]) if isinstance(data, dict) else []
    return [r["drive"] for r in records if isinstance(r, dict) and isinstance(r.get("drive"), dict)]


def adapt_restorer(manifest, gaussians, drive: dict, out: str | Path, config: AdaptConfig = AdaptConfig(), *,
                   guided: bool = True, sampler=None, progress: bool = True) -> dict:
    """Fine-tune the shipped restorer (``guided``: the guided one, on pairs with warps) on this
    drive's pairs, into ``out`` (pairs, weights, record, checkpoint), and fit its strength on the
    held-out frames' pairs sampled by ``sampler`` (default: the built-in one). Weights already
    finished there are reused, a checkpoint is resumed. Returns the training record (with
    ``strength``) plus ``reused``."""
    import time

    from ..io.atomic import write_text_atomic
    from ..scene.ground_truth import truth_camera
    from .config import SAMPLERS, CycleConfig
    from .cycle import cycle_config
    from .data import make_pairs
    from .train import RECORD, WEIGHTS, TrainConfig, train_restorer

    sampler = SAMPLERS["builtin"] if sampler is None else sampler

    out = Path(out)
    if (out / WEIGHTS).exists() and (out / RECORD).exists():
        record = json.loads((out / RECORD).read_text())
        if "strength" in record:
            return {**record, "reused": True}
    t0 = time.perf_counter()
    if not (out / PAIRS).exists():
        make_pairs(manifest, gaussians, config.offsets, out / PAIRS, camera=truth_camera(manifest).name,
                   cycle_offsets=config.cycle_offsets,
                   cycle_config=cycle_config(CycleConfig(iters=config.cycle_iters)),
                   warps=guided, sensor=config.sensor_pairs, drive=drive, progress=progress)
    left = None if config.max_seconds is None else max(config.max_seconds - (time.perf_counter() - t0), 0.0)
    held = validation_frames(pair_frames(out / PAIRS), config.validation_every)
    cfg = TrainConfig(steps=config.iters, lr=config.lr, warmup=config.warmup, seed=config.seed,
                      threads=config.threads, degraded_fraction=config.degraded_fraction,
                      init=str(shipped_weights(guided)), guide=guided, max_seconds=left,
                      holdout_frames=tuple(held))
    record = train_restorer(out / PAIRS, out, cfg, resume=True, progress=progress)
    pairs_seconds = round(time.perf_counter() - t0 - record["seconds"], 1)
    record["strength"] = _fit_strength(out, held, sampler, guided)
    write_text_atomic(out / RECORD, json.dumps(record, indent=1) + "\n")
    return {**record, "pairs_seconds": pairs_seconds, "reused": False}


def pair_frames(pairs: Path) -> list[int]:
    """The recorded frames a pairs file was made from (its metadata)."""
    from safetensors import safe_open

    with safe_open(str(pairs), "np") as f:
        return [int(i) for i in json.loads((f.metadata() or {}).get("frames", "[]"))]


def _fit_strength(out: Path, held: list[int], sampler, guided: bool) -> dict:
    """Fit the trained weights' strength and keep_warp on the ``held`` frames' pairs and write them
    into the weights (their sampler keeps that share of the correction, and the warp or not);
    ``{"strength": 1, "keep_warp": True}`` without them."""
    from .data import PairSet
    from .models import load_builtin, save_builtin
    from .strength import fit_strength
    from .train import WEIGHTS

    fit = None
    if held:
        restorer = load_builtin(out / WEIGHTS)
        fit = fit_strength(restorer, PairSet(out / PAIRS, held, held_out=True), sampler, guided=guided)
    if fit is None:
        return {"strength": 1.0, "keep_warp": True, "frames": held, "fit": None}
    save_builtin(out / WEIGHTS, restorer.net,
                 {**weights_meta(out / WEIGHTS), "strength": fit.strength, "keep_warp": fit.keep_warp}, half=True)
    return {"strength": fit.strength, "keep_warp": fit.keep_warp, "frames": held, "fit": fit.to_json()}
