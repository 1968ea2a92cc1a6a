"""The stages ``symdrive run`` executes: reconstruct, render, adapt, restore, refine, harmonize,
finetune, evaluate. Each is a thin call into the library that returns what it did and what it measured
(:class:`StageResult`); heavy modules are imported inside, so a plan that skips a stage never
loads its code (no diffusion model for a scene that needs none).

A new stage is a function here registered with :func:`stage` and its decision in ``plan.py``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

from ..diffusion.adapt import AdaptConfig
from ..diffusion.config import SAMPLERS, RefineConfig, SamplerConfig
from ..insertion.config import HarmonizeConfig, InpaintConfig, InsertionConfig
from ..scene.ground_truth import has_insertion_truth, has_lateral_truth, scorable_lateral_truth


@dataclass
class StageOptions:
    """Knobs that trade quality for time (``symdrive bench accuracy-time`` measures them)."""

    # Auto-regressive step d in metres, per chain, from the accuracy-vs-time table (docs/results.md):
    # the unguided chain keeps the paper's 0.5 (1.0 loses 2 to 5 lane-IoU points at 1 m); the
    # guided one scores at least as well at 1.0 as at 0.5 with half the restorations.
    ar_step: float = 0.5
    guided_ar_step: float = 1.0
    # Guide the chain by the recorded neighbours warped over the ground (diffusion.warp): its start
    # states and far conditions become those warps (method geo_ar_d<step>). It beats the unguided
    # chain at every offset on the demo's held-out lateral views (docs/results.md); a camera whose package
    # gives the warp no ground or no depth falls back to the unguided chain.
    geometry_guided: bool = True
    eval_methods: tuple[str, ...] = ("single_view", "ar_d0.5", "ar_d1.0")
    # The built-in restorer's measured sampler. Its memory budget (GiB one restorer evaluation
    # may use, harmonization's too; beyond it samples, then overlapping tiles, run in turn:
    # diffusion.tiling) is fixed, not read from the machine, so the run's cache key stays put.
    sampler: SamplerConfig = field(default_factory=lambda: replace(SAMPLERS["builtin"], max_memory_gib=4.0))
    refine: RefineConfig = field(default_factory=RefineConfig)
    harmonize: HarmonizeConfig = field(default_factory=HarmonizeConfig)
    inpaint: InpaintConfig = field(default_factory=InpaintConfig)  # what edits of recorded vehicles expose
    insertion: InsertionConfig = field(default_factory=InsertionConfig)  # its training views and fine-tune
    adapt: AdaptConfig = field(default_factory=AdaptConfig)  # the restorer's fine-tune on this drive


@dataclass
class StageResult:
    """What a stage did (its row in report.json's ``stages``) and what it measured (merged into
    ``metrics``: a list extends the rows earlier stages gave under the same name, as refinement's
    lateral rows join restoration's; anything else is set)."""

    details: dict = field(default_factory=dict)
    metrics: dict = field(default_factory=dict)


def merge_metrics(into: dict, metrics: dict) -> None:
    for name, value in metrics.items():
        if isinstance(value, list) and isinstance(into.get(name), list):
            into[name] = into[name] + value
        else:
            into[name] = value


STAGE_RUNNERS: dict[str, Callable[..., StageResult]] = {}


def stage(name: str):
    """Register a stage's runner under its plan name."""
    def register(fn):
        STAGE_RUNNERS[name] = fn
        return fn
    return register


@dataclass
class Shared:
    """What one stage hands to the next within a run (loaded once)."""

    background: object = None  # Gaussians
    background_path: Path | None = None  # a reconstruction this run fitted (the package had none)
    actors: dict = field(default_factory=dict)  # its recorded vehicles' Gaussians, by actor id
    shadows: dict | None = None  # their shadow layers, by actor id
    exposure: dict = field(default_factory=dict)  # its cameras' colour transforms, when it fitted them
    restorer: object = None
    drive: dict | None = None  # diffusion.adapt.drive_identity of the package and its reconstruction
    adapted: Path | None = None  # the folder of this drive's adapted restorer
    # by camera name: the geometry-guided chain's warper (None: the package gives it no ground or depth)
    warpers: dict = field(default_factory=dict)
    warper_errors: dict = field(default_factory=dict)  # by camera name: why it has none
    restored: list = field(default_factory=list)  # RestoredView, for refinement


def planned_cameras(ctx) -> list:
    """The package cameras this run renders, restores and harmonizes (``PlanOptions.cameras``)."""
    return [ctx.manifest.camera(name) for name in ctx.plan.cameras]


def background_path(ctx) -> Path | None:
    """The background splat PLY: the package's, or the one this run's reconstruct stage wrote."""
    if ctx.shared.background_path is not None:
        return ctx.shared.background_path
    return ctx.manifest.resolve(ctx.manifest.background_splats)


def exposure(ctx) -> dict:
    """The cameras' colour transforms: this run's reconstruction's, else those written beside the
    package's background splats by the reconstruction that made them (none: empty)."""
    from ..optim.exposure import read_exposure

    return ctx.shared.exposure or read_exposure(background_path(ctx).parent)


def background(ctx):
    from ..io.ply import read_splats

    if ctx.shared.background is None:
        ctx.shared.background = read_splats(background_path(ctx))
    return ctx.shared.background


def recorded_vehicles(ctx) -> dict:
    """The recorded vehicles' Gaussians by actor id: this run's reconstruction's, else the package's
    (existing actors with a splat PLY)."""
    from ..io.ply import read_splats

    if not ctx.shared.actors:
        ctx.shared.actors = {a.id: read_splats(ctx.manifest.resolve(a.splats)) for a in ctx.manifest.actors
                             if a.kind == "existing" and a.splats}
    return ctx.shared.actors


def recorded_shadows(ctx) -> dict:
    """The recorded vehicles' shadow layers by actor id: this run's reconstruction's, else the
    package's (``assets.shadow``)."""
    from ..shadows.layer import package_layers

    if ctx.shared.shadows is None:
        ctx.shared.shadows = package_layers(ctx.manifest)
    return ctx.shared.shadows


def restorer(ctx):
    """The shipped restorer on the run's device; where the plan adapts it, the adapted weights take
    the place of the weights they were fine-tuned from (the guided ones, or the default)."""
    from ..diffusion.models import load_builtin, load_restorer
    from ..diffusion.train import WEIGHTS

    if ctx.shared.restorer is None:
        ctx.shared.restorer = load_restorer()
        if ctx.plan.runs("adapt"):
            adapted = load_builtin(adapted_folder(ctx) / WEIGHTS)
            if adapted.guide_channels:
                ctx.shared.restorer.guided = adapted
            else:
                ctx.shared.restorer = adapted
        ctx.shared.restorer.to(ctx.device)
    return ctx.shared.restorer


def drive(ctx) -> dict:
    """The drive's identity (its recorded frames and reconstruction), hashed once per run."""
    from ..diffusion.adapt import drive_identity

    if ctx.shared.drive is None:
        ctx.shared.drive = drive_identity(ctx.manifest, background_path(ctx))
    return ctx.shared.drive


def warper(ctx, cam):
    """The geometry-guided chain's warper of ``cam`` over this run's background, built once per run
    (the adapt and restore stages share it); None where the option is off or the package gives the
    warp no ground or depth (the reason is kept in ``ctx.shared.warper_errors``)."""
    from ..diffusion.warp import WarpError, package_warper

    if ctx.options.geometry_guided and cam.name not in ctx.shared.warpers:
        try:
            ctx.shared.warpers[cam.name] = package_warper(ctx.manifest, cam, background(ctx))
        except WarpError as e:
            ctx.shared.warpers[cam.name] = None
            ctx.shared.warper_errors[cam.name] = str(e)
    return ctx.shared.warpers.get(cam.name)


def adapted_folder(ctx) -> Path:
    """Where this drive's adapted restorer lives: under a key of the drive, the adaptation's
    options and the code (shipped weights included), not under the run's key, so runs that only
    restore differently reuse it (unless they sample differently: the strength is fitted with the
    run's sampler)."""
    import hashlib
    import json
    from dataclasses import asdict

    from .cache_key import code_version
    from .outputs import ADAPT_CACHE

    if ctx.shared.adapted is None:
        o = ctx.options
        s = o.sampler
        deterministic = s.noise_free and s.n_start > 0  # then seed and samples play no part
        sampling = [s.steps, s.n_start, s.noise_free] + ([] if deterministic else [s.seed, s.samples])
        payload = {"drive": drive(ctx), "adapt": asdict(o.adapt), "guided": o.geometry_guided,
                   "sampler": sampling, "code": code_version()}
        key = hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:16]
        ctx.shared.adapted = ctx.tree.folder(ADAPT_CACHE, key)
    return ctx.shared.adapted


@stage("reconstruct")
def reconstruct_stage(ctx) -> StageResult:
    """Fit background Gaussians to the package's images (it had none); later stages read them
    from this run's output, the manifest stays as given on disk (its tracked vehicles and, where
    refined, its cameras placed at their refined poses in this run)."""
    from ..optim.reconstruct import reconstruct, with_fitted

    out = ctx.tree.folder("reconstruction")
    result = reconstruct(ctx.manifest, out, resume=(out / "checkpoint").exists(), progress=ctx.progress)
    with_fitted(ctx.manifest, result.poses, result.cameras)
    ctx.shared.background_path = out / "background.ply"
    ctx.shared.actors = result.actors
    ctx.shared.shadows = result.shadows
    ctx.shared.exposure = result.exposure
    return StageResult({"gaussians": len(result.gaussians), "actors": {k: len(g) for k, g in result.actors.items()},
                        "depth_weight": result.metrics["depth_weight"]})


@stage("render")
def render_stage(ctx) -> StageResult:
    """Every camera's every frame (frames already on disk are kept)."""
    from .scene_render import render_frames

    jobs = [(cam.name, fi) for cam in planned_cameras(ctx) for fi in ctx.plan.stage("render").frames]
    fitted = background(ctx) if ctx.shared.background_path is not None else None
    done = render_frames(ctx.manifest, ctx.plan, ctx.tree, jobs, ctx.device, ctx.progress, background=fitted,
                         actors=ctx.shared.actors, shadows=recorded_shadows(ctx))
    return StageResult({"frames_rendered": done, "frames_reused": len(jobs) - done})


@stage("inpaint")
def inpaint_stage(ctx) -> StageResult:
    """RePaint over what the edits of recorded vehicles expose, in each frame they were edited:
    their pixels where the drive saw them that no vehicle covers now, where no training frame saw
    the street behind them."""
    from tqdm import tqdm

    from ..insertion.exposed import edited_here, inpaint_region
    from ..io.images import read_image, write_image, write_mask
    from .outputs import ASSET_CACHE
    from .scene_render import SceneRenderer

    cfg = ctx.options.inpaint
    renderer = SceneRenderer(ctx.manifest, device=ctx.device, asset_cache=ctx.tree.folder(ASSET_CACHE),
                             background_gaussians=background(ctx), actor_gaussians=recorded_vehicles(ctx),
                             actor_shadows=recorded_shadows(ctx))
    inpaint = _harmonizer(ctx, cfg.harmonize)
    jobs = [(cam, fi) for cam in planned_cameras(ctx) for fi in ctx.plan.stage("inpaint").frames]
    pixels, n = 0, 0
    for cam, fi in tqdm(jobs, desc="inpaint", unit="frame", disable=not ctx.progress):
        path = ctx.tree.frame("inpaint", cam.name, fi)
        if path.exists():
            continue
        recorded = renderer.render(cam.name, fi, recorded=True)
        now = renderer.render(cam.name, fi)
        street = renderer.render(cam.name, fi, [])
        region = inpaint_region(ctx.manifest, renderer.view(cam.name, fi), recorded.instance, now.instance,
                                edited_here(ctx.manifest, fi), street.depth, cfg.dilate_px)
        if region is None:
            continue
        image = read_image(ctx.tree.frame("render", cam.name, fi), channels=3)
        write_mask(ctx.tree.frame("inpaint", cam.name, fi, ".region.png"), region.astype(np.float32))
        write_image(path, inpaint(image, region))
        pixels, n = pixels + int(region.sum()), n + 1
    return StageResult({"frames_inpainted": n, "pixels_inpainted": pixels})


@stage("adapt")
def adapt_stage(ctx) -> StageResult:
    """Fine-tune the shipped restorer on this drive's own pairs (the plan found its weights trained
    on another); the geometry-guided restorer where the package gives the warp, else the default."""
    from ..diffusion.adapt import adapt_restorer
    from ..scene.ground_truth import truth_camera

    m, opts = ctx.manifest, ctx.options
    guided = warper(ctx, truth_camera(m)) is not None
    folder = adapted_folder(ctx)
    record = adapt_restorer(m, background(ctx), drive(ctx), folder, opts.adapt, guided=guided,
                            sampler=opts.sampler, progress=ctx.progress)
    ctx.shared.restorer = None  # restorer() loads the adapted weights
    made = {} if record["reused"] else {"pairs_seconds": record["pairs_seconds"],
                                        "train_seconds": record["seconds"]}
    return StageResult({"reused": record["reused"], "guided": guided, "pairs": record["data"]["pairs"],
                        "steps": record["steps"], "final_loss": record["final_loss"],
                        "strength": record["strength"],
                        "weights": folder.relative_to(ctx.tree.root).as_posix(), **made})


@stage("restore")
def restore_stage(ctx) -> StageResult:
    """Restore every (frame, lateral offset) by the auto-regressive chain from the recorded view;
    with lateral ground truth, also score raw 3DGS and the ablations on those views."""
    from tqdm import tqdm

    from ..diffusion.restore import LateralChain, RestoredView
    from ..eval.restoration import run_lateral_restoration
    from ..eval.views import evaluate_lateral
    from ..io.images import read_image, write_image
    from ..scene.ground_truth import truth_camera
    from ..splat.render import SplatRenderer

    m, opts, decision = ctx.manifest, ctx.options, ctx.plan.stage("restore")
    g, model, sampler = background(ctx), restorer(ctx), opts.sampler
    render = SplatRenderer(g)  # one parameter conversion for scoring, chains and the remaining views
    default = chain_method(opts, guided=warper(ctx, truth_camera(m)) is not None)
    offsets, scored_frames = decision.offsets, ctx.plan.window  # scoring: every truth frame in the window
    done: set[tuple[str, int, float]] = set()
    chains: dict = {}  # one chain per (camera, frame): offsets share its prefix
    metrics, scored, unscored = {}, None, {}
    if ctx.plan.runs("evaluate") and has_lateral_truth(m):
        if truth_camera(m).name in ctx.plan.cameras:
            scored, why = scorable_lateral_truth(m, offsets, scored_frames)
        else:
            why = f"the lateral truth's camera {truth_camera(m).name!r} is not among the cameras run"
        unscored = {"lateral_not_scored": why} if why else {}
    if scored is not None:
        methods = tuple(dict.fromkeys((*opts.eval_methods, default)))
        res = run_lateral_restoration(scored, g, model, methods=methods, sampler=sampler, frames=scored_frames,
                                      progress=ctx.progress, warper=warper(ctx, truth_camera(m)),
                                      render=render)
        metrics["lateral"] = evaluate_lateral(scored, g, "raw_3dgs", scored_frames, render=render) + res.rows
        ctx.shared.restored = list(res.views[default])
        cam_name = truth_camera(m).name
        chains = {(cam_name, fi): chain for fi, chain in res.chains.items()}
        for v in ctx.shared.restored:
            write_image(ctx.tree.frame("restore", f"{cam_name}/{v.offset_m:+g}", v.frame), v.image)
            done.add((cam_name, v.frame, round(v.offset_m, 6)))
    jobs = [(cam, fi, off) for cam in planned_cameras(ctx) for fi in decision.frames
            for off in offsets if (cam.name, fi, round(off, 6)) not in done]
    for cam, fi, off in tqdm(jobs, desc="restore", unit="view", disable=not ctx.progress or not jobs):
        path = ctx.tree.frame("restore", f"{cam.name}/{off:+g}", fi)
        if path.exists():
            image = read_image(path, channels=3)
        else:
            if (cam.name, fi) not in chains:
                chains[cam.name, fi] = LateralChain.for_frame(m, cam, fi, model, render, sampler, warper(ctx, cam))
            guided = warper(ctx, cam) is not None
            image = chains[cam.name, fi].restore(off, chain_step(opts, guided), guided=guided)
            write_image(path, image)
        ctx.shared.restored.append(RestoredView.shifted(cam, fi, off, image))
    off = {"geometry_guided_off": dict(ctx.shared.warper_errors)} if ctx.shared.warper_errors else {}
    grounds = {name: w.ground.summary() for name, w in ctx.shared.warpers.items() if w is not None}
    return StageResult({"views_restored": len(ctx.shared.restored), "method": default, **off,
                        **({"ground": grounds} if grounds else {}), **unscored}, metrics)


def chain_step(opts: StageOptions, guided: bool) -> float:
    """The step d of the pipeline's chain, guided or not (each measured on its own)."""
    return opts.guided_ar_step if guided else opts.ar_step


def chain_method(opts: StageOptions, guided: bool) -> str:
    """The method name of the pipeline's chain (``geo_ar_d1.0``, ``ar_d0.5``, ``single_view``...)."""
    step = chain_step(opts, guided)
    return ("geo_" if guided else "") + (f"ar_d{float(step)!r}" if step > 0 else "single_view")


@stage("refine")
def refine_stage(ctx) -> StageResult:
    """Fine-tune the background on the recorded views plus the restored lateral views. A refined
    PLY already in the folder (a run that stopped after refining) is reused, not refitted."""
    from ..diffusion.refine import refine_gaussians
    from ..eval.views import evaluate_lateral
    from ..io.ply import read_splats, write_splats

    path = ctx.tree.path("refine", "background.ply")
    if path.exists():
        refined, details = read_splats(path), {"reused": True}
    else:
        refined, stats = refine_gaussians(ctx.manifest, background(ctx), ctx.shared.restored,
                                          ctx.options.refine, progress=ctx.progress)
        write_splats(path, refined)
        # The loop's own time is part of the stage's row "seconds".
        details = {k: v for k, v in stats.items() if isinstance(v, (int, float)) and k not in ("seconds", "iters")}
    metrics = {}
    scored = None
    if ctx.plan.runs("evaluate") and has_lateral_truth(ctx.manifest):
        scored = scorable_lateral_truth(ctx.manifest, ctx.plan.stage("restore").offsets, ctx.plan.window)[0]
    if scored is not None:
        metrics["lateral"] = evaluate_lateral(scored, refined, "refined", ctx.plan.window)
    return StageResult({"iterations": ctx.options.refine.iters, **details}, metrics)


def _inserted_region(ctx, cam, fi) -> np.ndarray | None:
    """Vehicle pixels (from the render's instance masks) ∪ each vehicle's shadow region."""
    from ..io.images import read_mask
    from ..shadows.region import harmonization_region, shadow_region

    m = ctx.manifest
    region = None
    for aid in ctx.plan.stage("harmonize").actors:
        mpath = ctx.tree.frame("masks", cam.name, fi, actor=aid)
        if aid not in ctx.plan.visible[cam.name][fi] or not mpath.exists():
            continue
        actor = m.actor(aid)
        shadow = None
        if ctx.plan.runs("cast_shadow") and actor.wlh is not None:
            cf = cam.frames[fi]
            shadow = shadow_region(actor.pose(fi), actor.wlh, m.effects.sun_direction, cf.camera_to_world, cf.K,
                                   cam.width, cam.height)
        r = harmonization_region(read_mask(mpath), shadow)
        region = r if region is None else region | r
    return region


def _harmonizer(ctx, config=None):
    """The RePaint sampler on the run's restorer: ``config`` (default: the harmonization's)."""
    from ..insertion.harmonizer import restorer_harmonizer

    o = ctx.options
    return restorer_harmonizer(restorer(ctx), config or o.harmonize, max_memory_gib=o.sampler.max_memory_gib)


@stage("harmonize")
def harmonize_stage(ctx) -> StageResult:
    """RePaint harmonization of each rendered frame that shows an inserted vehicle."""
    from tqdm import tqdm

    from ..io.images import read_image, write_image, write_mask

    harmonizer = _harmonizer(ctx)
    jobs = [(cam, fi) for cam in planned_cameras(ctx) for fi in ctx.plan.stage("harmonize").frames]
    n = 0
    for cam, fi in tqdm(jobs, desc="harmonize", unit="frame", disable=not ctx.progress):
        path = ctx.tree.frame("harmonize", cam.name, fi)
        region = _inserted_region(ctx, cam, fi)
        if path.exists() or region is None or not region.any():
            continue
        inpainted = ctx.tree.frame("inpaint", cam.name, fi)  # an edit of a recorded vehicle filled first
        image = read_image(inpainted if inpainted.exists() else ctx.tree.frame("render", cam.name, fi), channels=3)
        write_mask(ctx.tree.frame("harmonize", cam.name, fi, ".region.png"), region.astype(np.float32))
        write_image(path, harmonizer(image, region))
        n += 1
    return StageResult({"frames_harmonized": n})


@stage("finetune")
def finetune_stage(ctx) -> StageResult:
    """Colour/opacity-only fine-tune of each inserted vehicle on its harmonized frames."""
    from ..insertion.insert import finetune_sample, insert_frame
    from ..insertion.placements import camera_view
    from ..io.images import read_image
    from ..io.ply import write_splats
    from ..optim.finetune import finetune_colors
    from ..splat.tensors import GaussianTensors
    from .outputs import ASSET_CACHE
    from .scene_render import actor_splats

    cfg = ctx.options.insertion
    bg = GaussianTensors.from_gaussians(background(ctx))
    written = []
    for aid in ctx.plan.stage("finetune").actors:
        out = ctx.tree.path("finetune", f"{aid}.ply")
        if out.exists():
            written.append(aid)
            continue
        actor = ctx.manifest.actor(aid)
        vehicle = actor_splats(ctx.manifest, actor, ctx.tree.folder(ASSET_CACHE))
        samples = []
        for cam in planned_cameras(ctx):
            for fi in ctx.plan.stage("harmonize").frames:
                target_path = ctx.tree.frame("harmonize", cam.name, fi)
                if aid not in ctx.plan.visible[cam.name][fi] or not target_path.exists():
                    continue
                frame = insert_frame(ctx.manifest, bg, vehicle, actor.pose(fi), actor.wlh,
                                     camera_view(ctx.manifest, fi, cam.name))
                if frame.region.any():
                    samples.append(finetune_sample(frame, read_image(target_path, channels=3), bg, vehicle, cfg))
        if samples:
            write_splats(out, finetune_colors(vehicle, samples, cfg.finetune, progress=ctx.progress).gaussians)
            written.append(aid)
    return StageResult({"actors_finetuned": len(written)})


@stage("evaluate")
def evaluate_stage(ctx) -> StageResult:
    """Every metric the package's ground truth allows: held-out reconstruction, insertion; in
    the run's frame window, where it has one."""
    from ..eval.insertion import evaluate_insertion
    from ..eval.views import evaluate_heldout
    from ..insertion.placements import held_out_placements
    from ..scene.ground_truth import split_frames

    m, opts, details, metrics = ctx.manifest, ctx.options, {}, {}
    window = ctx.plan.window
    has_background = background_path(ctx) is not None
    heldout = [f for f in split_frames(m)[1] if window is None or f in window]
    if has_background and heldout and all(c.frames[0].image for c in m.cameras):
        metrics["reconstruction"] = evaluate_heldout(m, background(ctx), heldout, actors=recorded_vehicles(ctx),
                                                     shadows=recorded_shadows(ctx), exposure=exposure(ctx))
    placed = has_insertion_truth(m) and any(window is None or p.frame in window for p in held_out_placements(m))
    if placed and has_background:
        harmonizer = _harmonizer(ctx) if ctx.plan.runs("harmonize") else None
        cfg = replace(opts.insertion, assets_out=ctx.tree.folder("insertion_assets"))
        metrics["insertion"] = evaluate_insertion(m, background(ctx), harmonizer=harmonizer, config=cfg,
                                                  details=details, progress=ctx.progress, frames=window)
    return StageResult({"metrics": sorted(metrics), **({"timings": details["timings"]} if "timings" in details else {})},
                       metrics)
