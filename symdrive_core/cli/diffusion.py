"""Restorer subcommands: ``make-pairs``, ``train-restorer`` and ``restore``.

Registration imports nothing heavy: torch and diffusers load inside the handlers, so commands
that need no diffusion model never pay for (or depend on) them.
"""

from __future__ import annotations

import argparse
import math
import re
from dataclasses import replace
from pathlib import Path

from ..diffusion.config import (
    FLUX_PROMPT_TOKENS,
    SAMPLERS,
    CycleConfig,
    FluxTrainConfig,
    RefineConfig,
    SamplerConfig,
    TrainConfig,
)
from ..diffusion.defaults import EVALUATED_METHODS
from ..pipeline.outputs import output_file, output_folder, own_folder
from ..pipeline.stages import StageOptions, chain_step
from . import (
    add_frames_option,
    add_offsets_option,
    add_quiet_option,
    add_renamed_option,
    count_int,
    default_of,
    device_arg,
    distances_arg,
    given,
    positive_int,
    positive_number,
    seed_int,
    share_above_zero,
    unit_fraction,
)

MIN_CHAIN_STEP_M = 0.01  # a finer chain step is thousands of restorer passes per view


def _floats(text: str) -> list[float]:
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from exc


def _names(text: str) -> list[str]:
    """Comma-separated lateral methods: single_view, ar_d<metres>, warp, and geo_ + the first two."""
    names = [v.strip() for v in text.split(",") if v.strip()]
    bad = [n for n in names if not re.fullmatch(r"warp|(geo_)?(single_view|ar_d\d*\.?\d+)", n)]
    if not names or bad:
        raise argparse.ArgumentTypeError(f"unknown method {bad[0] if bad else text!r} (expected single_view, "
                                         "ar_d<metres>, warp, geo_single_view or geo_ar_d<metres>)")
    return names


def _signed_offsets(text: str) -> list[float]:
    values = _floats(text)
    if not values or any(v == 0 or not math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected finite non-zero signed offsets in metres, got {text!r}")
    return values


def _chain_step_arg(value: str) -> float:
    """``--step``: 0 (one jump, single view) or at least a centimetre."""
    try:
        x = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of metres, got {value!r}") from None
    if not (x == 0 or MIN_CHAIN_STEP_M <= x < math.inf):
        raise argparse.ArgumentTypeError(f"must be 0 (single view) or a finite step of at least "
                                         f"{MIN_CHAIN_STEP_M} m, got {value}")
    return x


def _network_output(value: str) -> str:
    if value not in ("skip", "v"):
        raise argparse.ArgumentTypeError(f"expected skip or v, got {value!r}")
    return value


def _train_default(name: str) -> str:
    """``default V`` of the built-in trainer's field ``name``, and Flux's where it has another."""
    builtin = default_of(TrainConfig, name)
    flux = default_of(FluxTrainConfig, name) if hasattr(FluxTrainConfig, name) else "None"
    return f"default {builtin}" + ("" if flux in (builtin, "None") else f"; flux {flux}")


def _per_backend(name: str) -> str:
    """The sampler field ``name`` of each backend, as ``5 builtin, 50 flux``."""
    return ", ".join(f"{default_of(sampler, name)} {backend}" for backend, sampler in SAMPLERS.items())


def add_commands(sub) -> None:
    from . import add_external_assets_option

    p = sub.add_parser(
        "make-pairs", help="render restorer training pairs (I_-d, I_d) -> I_0 from a reconstruction"
    )
    p.add_argument("package", help="scene package directory or its manifest.json")
    p.add_argument(
        "--gaussians", type=Path, metavar="PLY", help="reconstruction PLY (default: the manifest's background splats)"
    )
    p.add_argument(
        "--offsets", type=distances_arg, default=[0.5, 1.0, 1.5, 2.0, 2.5, 3.0], help="distances d in metres"
    )
    add_frames_option(p, help="recorded frames (default: the training frames)")
    p.add_argument(
        "--cycle",
        type=_signed_offsets,
        default=[],
        help="lateral offsets (m, signed) of cycle reconstructions whose renders at the recorded "
        "cameras become degraded starts (default: none)",
    )
    p.add_argument("--cycle-iters", type=positive_int,
                   help=f"iterations of each cycle reconstruction (default {default_of(CycleConfig, 'iters')})")
    p.add_argument("--cycle-max-gaussians", type=positive_int,
                   help=f"densification cap of each cycle reconstruction "
                        f"(default {default_of(CycleConfig, 'max_gaussians')})")
    p.add_argument("--warps", action="store_true",
                   help="also each frame's geometry-guided warp from the other frames (needs --cycle), "
                   "for training with --guide")
    p.add_argument("--sensor", action="store_true",
                   help="also pairs whose target a rig's second camera recorded at these frames (lateral "
                   "truth imported with --lateral-truth; needs --cycle)")
    p.add_argument("--out", type=Path, required=True, help="pairs file to write (.safetensors)")
    add_quiet_option(p)
    add_external_assets_option(p)
    p.set_defaults(func=_make_pairs)

    p = sub.add_parser("train-restorer", help="train the built-in restorer on pairs files (CPU)")
    p.add_argument("pairs", type=Path, nargs="+",
                   help="pairs files from `symdrive make-pairs` (several: a family of streets, drawn as one set)")
    p.add_argument("--out", type=Path, required=True, help="folder for weights, record and checkpoint")
    add_renamed_option(p, "--iters", "--steps", type=positive_int,
                       help=f"training iterations ({_train_default('steps')})")
    paper = SamplerConfig()
    for flag, kind, text in (
        ("--batch", positive_int, f"crops per iteration ({_train_default('batch')})"),
        ("--crop", positive_int, f"square crop size in pixels ({_train_default('crop')})"),
        ("--lr", positive_number, f"peak learning rate ({_train_default('lr')})"),
        ("--ema", unit_fraction, f"EMA decay of the shipped weights (default {default_of(TrainConfig, 'ema')})"),
        ("--width", positive_int, f"UNet base width (default {default_of(TrainConfig, 'width')})"),
        ("--seed", seed_int, f"seed of every batch and noise draw ({_train_default('seed')})"),
        ("--threads", positive_int, f"torch threads ({_train_default('threads')})"),
        ("--checkpoint-every", positive_int,
         f"iterations between checkpoints ({_train_default('checkpoint_every')})"),
        ("--t-max", share_above_zero, f"train on noise levels t <= T_MAX (default {default_of(TrainConfig, 't_max')}; "
                           f"sampling from N_start {paper.n_start} of {paper.steps} starts at "
                           f"{1 - paper.n_start / paper.steps:g})"),
        ("--full-fraction", unit_fraction,
         f"share of each batch drawn on all of t in [0, 1] (default {default_of(TrainConfig, 'full_fraction')})"),
        ("--output", _network_output, "network output: skip (correction on the condition mean) or v "
                          f"(default {default_of(TrainConfig, 'output')})"),
        ("--degraded-fraction", unit_fraction, "share of each batch started from a degraded render, when the pairs have "
                                       f"cycles ({_train_default('degraded_fraction')})"),
        ("--init", str, "restorer weights to continue from (default: a fresh network)"),
    ):
        p.add_argument(flag, type=kind, help=text)
    p.add_argument("--guide", action="store_true",
                   help="the geometry-guided warp and its mask as a condition (pairs from make-pairs --warps); "
                   "unguided --init weights are extended with zero-initialised inputs")
    p.add_argument("--resume", action="store_true",
                   help="continue from OUT/checkpoint.safetensors (flux: OUT/flux_checkpoint.safetensors)")
    # Flux.1-dev + LoRA (the paper's recipe; GPU): diffusion.flux_train, defaults in FluxTrainConfig
    p.add_argument("--backend", choices=["builtin", "flux"], default="builtin",
                   help="builtin: the small UNet (CPU); flux: a LoRA on FLUX.1-dev (GPU, local weights)")
    p.add_argument("--flux-transformer", help="flux: FLUX.1-dev transformer folder (diffusers layout)")
    p.add_argument("--flux-vae", help="flux: FLUX.1-dev VAE folder (diffusers layout)")
    p.add_argument("--prompt", help="flux: prompt-embedding .safetensors from `symdrive flux-prompt`")
    p.add_argument("--rank", type=positive_int, help=f"flux: LoRA rank (default {default_of(FluxTrainConfig, 'rank')})")
    p.add_argument("--lora-alpha", type=positive_number, help="flux: LoRA alpha (default: the rank)")
    p.add_argument("--lora-targets", type=lambda t: tuple(v.strip() for v in t.split(",") if v.strip()),
                   help="flux: comma-separated module names the LoRA adapts (default to_q,to_k,to_v,to_out.0)")
    p.add_argument("--grad-accum", type=positive_int, help="flux: batches accumulated per iteration "
                   f"(default {default_of(FluxTrainConfig, 'grad_accum')})")
    p.add_argument("--warmup", type=count_int, help=f"learning-rate warm-up iterations ({_train_default('warmup')})")
    p.add_argument("--mixed-precision", choices=["auto", "no", "bf16", "fp16"],
                   help="flux: auto (default) is bf16 on CUDA, float32 on the CPU")
    p.add_argument("--no-gradient-checkpointing", action="store_true", help="flux: keep all activations")
    add_quiet_option(p)
    p.set_defaults(func=_train)

    p = sub.add_parser("flux-prompt", help="write the prompt-embedding file of --backend flux from local T5 / CLIP")
    p.add_argument("--text-encoders", type=Path, required=True,
                   help="folder with text_encoder/, tokenizer/ (CLIP) and text_encoder_2/, tokenizer_2/ (T5), "
                        "as in FLUX.1-dev")
    p.add_argument("--out", type=Path, required=True, help=".safetensors to write")
    p.add_argument("--text", help="the prompt (default: diffusion.flux_prompt.DEFAULT_PROMPT)")
    p.add_argument("--max-length", type=positive_int, help=f"T5 tokens (default {FLUX_PROMPT_TOKENS}, FLUX.1-dev's)")
    p.add_argument("--device", default="cpu", type=device_arg, help="torch device (cpu, cuda, cuda:N)")
    p.set_defaults(func=_flux_prompt)

    p = sub.add_parser("restore", help="restore lateral views auto-regressively (and evaluate / refine)")
    p.add_argument("package", help="scene package directory or its manifest.json")
    p.add_argument(
        "--gaussians", type=Path, metavar="PLY", help="reconstruction PLY (default: the manifest's background splats)"
    )
    add_offsets_option(p, default=[0.5, 1.0, 1.5, 2.0, 3.0],
                       help="the views to restore (with --evaluate, the views --refine trains on; scoring "
                            "covers every offset with ground truth)")
    p.add_argument("--step", type=_chain_step_arg,
                   help=f"chain step d in metres (0 = single-view; default {default_of(StageOptions, 'ar_step')}, "
                        f"{default_of(StageOptions, 'guided_ar_step')} with --geometry-guided)")
    add_frames_option(p, help="recorded frames (default: all; with --evaluate, those with lateral ground truth)")
    p.add_argument("--steps", type=positive_int, help=f"sampler steps (default: {_per_backend('steps')})")
    p.add_argument("--n-start", type=count_int,
                   help=f"start step of the noise initialisation (default: {_per_backend('n_start')})")
    p.add_argument("--seed", type=seed_int, help=f"sampler noise seed (default {default_of(SamplerConfig, 'seed')})")
    p.add_argument("--samples", type=positive_int,
                   help="average this many samples per view: the posterior mean, higher PSNR for up to that many "
                        f"times the work (default: {_per_backend('samples')})")
    p.add_argument("--noise-free", action=argparse.BooleanOptionalAction,
                   help="start from the initialisation without noise: one deterministic sample in place of the "
                        f"mean of --samples (default: {_per_backend('noise_free')})")
    p.add_argument("--strength", type=unit_fraction,
                   help="share of the restorer's correction each view keeps, 0 (its start) to 1 (the full "
                        "correction) (default: what the weights record, fitted by an adaptation, else 1)")
    p.add_argument("--keep-warp", action=argparse.BooleanOptionalAction,
                   help="a guided restorer's view keeps the warp where the recorded frames saw the ground "
                        "(default: what the weights record, chosen by an adaptation, else on)")
    p.add_argument("--max-memory", type=positive_number, metavar="GiB",
                   help="memory for one restorer evaluation; larger images run on overlapping tiles "
                        f"(default {default_of(StageOptions, 'sampler.max_memory_gib')})")
    p.add_argument("--out", type=Path, required=True,
                   help="output folder: restored views and restored.json, or metrics.json with --evaluate")
    p.add_argument(
        "--evaluate",
        action="store_true",
        help="score raw 3DGS and each of --methods against the package's lateral ground truth",
    )
    p.add_argument("--methods", type=_names,
                   help="with --evaluate: comma-separated methods (default: " + ",".join(EVALUATED_METHODS) + "; "
                        "warp = the recorded neighbours warped over the ground, geo_* = the chain guided by it)")
    p.add_argument("--geometry-guided", action="store_true",
                   help="restore (and --refine on) the views by the chain guided by the recorded neighbours "
                        "warped over the ground (geo_ar_d<step>)")
    p.add_argument(
        "--refine",
        action="store_true",
        help="with --evaluate: refine the 3DGS on the restored views, and (the control) on the recorded views alone",
    )
    p.add_argument("--refine-iters", type=positive_int,
                   help=f"refinement iterations of --refine (default {default_of(RefineConfig, 'iters')})")
    add_frames_option(p, "--refine-frames",
                      help="recorded frames whose restored lateral views --refine trains on (default: all)")
    p.add_argument("--backend", choices=["builtin", "flux"], default="builtin",
                   help="restorer: builtin (the shipped network) or flux (FLUX.1-dev from the files named below)")
    p.add_argument("--weights", type=Path, help="built-in restorer weights (default: the shipped ones)")
    p.add_argument("--flux-transformer", help="FLUX.1-dev transformer folder (diffusers layout)")
    p.add_argument("--flux-vae", help="FLUX.1-dev VAE folder (diffusers layout)")
    p.add_argument("--flux-lora", help="restorer LoRA .safetensors")
    p.add_argument("--flux-prompt", help=".safetensors with prompt_embeds and pooled_prompt_embeds")
    p.add_argument("--threads", type=positive_int, default=1, help="torch threads (default %(default)s)")
    add_quiet_option(p)
    add_external_assets_option(p)
    p.set_defaults(func=_restore)


def _reconstruction(args):
    """The package, and the reconstruction PLY the command renders (``--gaussians``, else the manifest's)."""
    from ..errors import InputError
    from ..scene import check_files, load_manifest

    manifest = load_manifest(args.package, allow_external=args.allow_external_assets)
    check_files(manifest)  # every file it names, ground truth included, before any long work
    ply = args.gaussians or manifest.resolve(manifest.background_splats)
    if ply is None:
        raise InputError(
            manifest.path or manifest.root,
            "no reconstruction: pass --gaussians or run `symdrive reconstruct`",
            "background.splats",
        )
    return manifest, ply


def _load_scene(args):
    from ..io.ply import read_splats

    manifest, ply = _reconstruction(args)
    return manifest, read_splats(ply, drop_invalid=True)


def _make_pairs(args) -> int:
    from ..diffusion.adapt import drive_identity
    from ..diffusion.cycle import cycle_config
    from ..diffusion.data import make_pairs
    from ..errors import InputError
    from ..io.ply import read_splats

    if args.warps and not args.cycle:
        raise InputError("make-pairs", "needs --cycle: the cycle reconstructions' degraded starts fill what "
                         "no frame's warp sees", "--warps")
    if args.sensor and not args.cycle:
        raise InputError("make-pairs", "needs --cycle: every pair with a start needs the cycle reconstructions' "
                         "degraded starts", "--sensor")
    output_file(args.out)
    manifest, ply = _reconstruction(args)
    _check_frames(manifest, args)
    if args.sensor:
        _check_sensor_truth(manifest, args.frames)
    cycle = cycle_config(CycleConfig(**given(args, iters="cycle_iters", max_gaussians="cycle_max_gaussians")))
    out = make_pairs(
        manifest, read_splats(ply, drop_invalid=True), args.offsets, args.out, frames=args.frames,
        cycle_offsets=args.cycle, cycle_config=cycle, warps=args.warps, sensor=args.sensor,
        drive=drive_identity(manifest, ply),
        progress=not args.quiet,
    )
    print(f"wrote {out}")
    return 0


def _train(args) -> int:
    from ..diffusion.train import TrainConfig, train_restorer
    from . import print_json

    output_folder(args.out)
    if args.backend == "flux":
        return _train_flux(args)
    flux_only = ("flux_transformer", "flux_vae", "prompt", "rank", "lora_alpha", "lora_targets", "grad_accum",
                 "mixed_precision")
    given = [n for n in flux_only if getattr(args, n) is not None] + (["no_gradient_checkpointing"]
                                                                       if args.no_gradient_checkpointing else [])
    if given:
        from ..errors import InputError

        raise InputError("train-restorer", "needs --backend flux", "--" + given[0].replace("_", "-"))

    cfg = TrainConfig()
    names = ("batch", "crop", "lr", "ema", "width", "seed", "threads", "checkpoint_every")
    for name in (*names, "t_max", "full_fraction", "output", "degraded_fraction", "init", "warmup"):
        if getattr(args, name) is not None:
            setattr(cfg, name, getattr(args, name))
    if args.iters is not None:
        cfg.steps = args.iters
    cfg.guide = args.guide
    record = train_restorer(args.pairs, args.out, cfg, resume=args.resume, command=args.invocation,
                            progress=not args.quiet)
    print_json({k: record[k] for k in ("steps", "final_loss", "seconds", "data")})
    return 0


def _train_flux(args) -> int:
    from ..diffusion.flux_train import FluxTrainConfig, train_flux_lora
    from ..errors import InputError
    from . import print_json

    builtin_only = ("ema", "width", "t_max", "full_fraction", "output", "init")
    for name in builtin_only:
        if getattr(args, name) is not None:
            raise InputError("train-restorer", "not used by --backend flux", "--" + name.replace("_", "-"))
    if args.guide:
        raise InputError("train-restorer", "not used by --backend flux", "--guide")
    cfg = FluxTrainConfig()
    names = ("batch", "crop", "lr", "seed", "threads", "checkpoint_every", "rank", "warmup",
             "grad_accum", "mixed_precision", "degraded_fraction")
    for name in names:
        if getattr(args, name) is not None:
            setattr(cfg, name, getattr(args, name))
    if args.iters is not None:
        cfg.steps = args.iters
    if len(args.pairs) > 1:
        raise InputError("train-restorer", "--backend flux trains on one pairs file", "pairs")
    if args.lora_alpha is not None:
        cfg.alpha = args.lora_alpha
    if args.lora_targets is not None:
        cfg.targets = args.lora_targets
    cfg.gradient_checkpointing = not args.no_gradient_checkpointing
    record = train_flux_lora(args.pairs[0], args.out, args.flux_transformer, args.flux_vae, args.prompt, cfg,
                             resume=args.resume, command=args.invocation, progress=not args.quiet)
    print_json({k: record[k] for k in ("steps", "final_loss", "seconds", "seconds_per_step", "peak_gpu_memory_gib",
                                       "data")})
    return 0


def _flux_prompt(args) -> int:
    from ..diffusion.flux_prompt import DEFAULT_PROMPT, write_prompt_file

    output_file(args.out)
    out = write_prompt_file(args.text_encoders, args.out, args.text or DEFAULT_PROMPT, device=args.device,
                            **given(args, "max_length"))
    print(f"wrote {out}")
    return 0


def _restore(args) -> int:
    import json

    import torch

    from ..diffusion.models import load_restorer
    from ..errors import SymDriveError
    from ..io.atomic import write_text_atomic

    # the backend's sampler with the pipeline's memory budget, then what the command line set
    default = replace(SAMPLERS[args.backend], max_memory_gib=StageOptions().sampler.max_memory_gib)
    sampler = replace(default, **given(args, "steps", "n_start", "seed", "samples", "noise_free", "strength",
                                         "keep_warp", max_memory_gib="max_memory"))
    steps, n_start = sampler.steps, sampler.n_start
    tree = own_folder(args.out)
    if n_start >= steps:
        raise SymDriveError(f"--n-start {n_start}{' (the default)' if args.n_start is None else ''} must be "
                            f"below --steps {steps}: the sampler starts at step n_start of steps")
    if args.step is None:
        args.step = chain_step(StageOptions(), args.geometry_guided)
    torch.set_num_threads(args.threads)
    manifest, gaussians = _load_scene(args)
    _check_frames(manifest, args)
    _check_truth(manifest, args)
    restorer = load_restorer(
        args.backend,
        args.weights,
        **(
            {
                "transformer": args.flux_transformer,
                "vae": args.flux_vae,
                "lora": args.flux_lora,
                "prompt": args.flux_prompt,
            }
            if args.backend == "flux"
            else {}
        ),
    )
    if args.evaluate:
        metrics = _evaluate(args, tree, manifest, gaussians, restorer, sampler)
        write_text_atomic(tree.path("metrics.json"), json.dumps(metrics, indent=1) + "\n")
        print(json.dumps(metrics["lateral"], indent=1))
        return 0
    index = _restore_frames(args, tree, manifest, gaussians, restorer, sampler)
    write_text_atomic(tree.path("restored.json"), json.dumps(index, indent=1) + "\n")
    print(f"wrote {len(index['views'])} restored views to {args.out}")
    return 0


def _check_frames(manifest, args) -> None:
    """--frames / --refine-frames must name frames of the camera that is shifted sideways (every
    camera has the package's frames)."""
    from ..errors import InputError
    from ..scene.ground_truth import truth_camera

    cam = truth_camera(manifest)
    for option, frames in (("--frames", args.frames), ("--refine-frames", getattr(args, "refine_frames", None))):
        bad = [f for f in frames or () if not 0 <= f < len(cam.frames)]
        if bad:
            raise InputError(manifest.path or manifest.root, f"{option} {bad[0]} is not a frame of camera "
                             f"{cam.name!r} (0 to {len(cam.frames) - 1})", f"cameras.{cam.name}.frames")


def _check_sensor_truth(manifest, frames) -> None:
    """--sensor asks for the pairs a rig's second camera recorded: say so when there are none
    (the adaptation, which asks wherever there are some, does without)."""
    from ..diffusion.sensor_pairs import sensor_views
    from ..errors import InputError
    from ..scene.ground_truth import split_frames

    cam = manifest.cameras[0]  # the camera make-pairs shifts
    if not sensor_views(manifest, cam.name, split_frames(manifest)[0] if frames is None else frames):
        raise InputError(manifest.path or manifest.root, f"--sensor: no recorded camera gave lateral truth of camera "
                         f"{cam.name!r} at these frames (a rig imported with --lateral-truth does)",
                         "ground_truth.lateral")


def _check_truth(manifest, args) -> None:
    """--evaluate scores against the lateral ground truth, which imported packages lack: say so
    before the restorer loads, and which frames asked for have none. --refine only runs inside the
    evaluation, and the options of the two only with them."""
    import warnings

    from ..errors import InputError
    from ..eval.views import lateral_targets

    needs = {"--methods": ("evaluate", args.methods), "--refine-iters": ("refine", args.refine_iters),
             "--refine-frames": ("refine", args.refine_frames)}
    for option, (mode, value) in needs.items():
        if value is not None and not getattr(args, mode):
            raise InputError("restore", f"is used by --{mode}, which is not given", option)
    if args.evaluate:
        targets = lateral_targets(manifest, args.frames,
                                  "restore --evaluate needs it; drop --evaluate to restore without scoring")
        scored = {v.frame for v in targets}
        if unscored := [f for f in args.frames or () if f not in scored]:
            warnings.warn(f"frame(s) {', '.join(map(str, unscored))} have no lateral ground truth: not scored",
                          stacklevel=2)
    elif args.refine:
        raise InputError("restore", "needs --evaluate (`symdrive run` refines a package without ground truth)",
                         "--refine")


def _restore_frames(args, tree, manifest, gaussians, restorer, sampler) -> dict:
    from ..diffusion.restore import restore_lateral_views
    from ..io.images import write_image
    from ..scene.ground_truth import truth_camera

    cam = truth_camera(manifest)
    views = restore_lateral_views(manifest, gaussians, restorer, args.frames, args.offsets, args.step,
                                  sampler=sampler, progress=not args.quiet, guided=args.geometry_guided)
    index = []
    for v in views:
        rel = f"{v.offset_m:+.2f}/{v.frame:06d}.png"
        write_image(tree.path(rel), v.image)
        index.append({"frame": v.frame, "offset_m": v.offset_m, "image": rel, "K": v.K.tolist(),
                      "camera_to_world": v.camera_to_world.tolist(), "width": v.width, "height": v.height})
    return {"camera": cam.name, "step_m": args.step, "sampler": vars(sampler), "views": index}


def _evaluate(args, tree, manifest, gaussians, restorer, sampler) -> dict:
    from ..eval.restoration import RefineStudy, restoration_study
    from ..io.ply import write_splats

    iters = replace(RefineConfig(), **given(args, iters="refine_iters")).iters
    refine = (RefineStudy(args.offsets, args.step, args.refine_frames, iters, args.geometry_guided)
              if args.refine else None)
    methods = tuple(args.methods or EVALUATED_METHODS)
    metrics, refined = restoration_study(manifest, gaussians, restorer, methods=methods, sampler=sampler,
                                         frames=args.frames, refine=refine, progress=not args.quiet)
    if refined is not None:
        write_splats(tree.path("refined.ply"), refined)
    return metrics
