"""The knobs ``symdrive bench accuracy-time`` measures, each against a package's ground truth.

Renderer knobs (antialiasing, footprint extent, SH degree, precision, resolution) and whole
reconstructions (resolution schedule, end of densification: :mod:`.reconstruction`)
are scored on the package's held-out recorded frames; restorer knobs (sampler steps and ``N_start``, the
auto-regressive step ``d``) on its lateral views; fine-tune iterations on its held-out insertion
placements. A group whose ground truth the package lacks is left out and the reason returned.
Seconds are the work itself (per frame, per view, per placement or per run), not loading.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
import torch

from ..diffusion.harmonize import CROP_MARGIN
from ..pipeline.stages import StageOptions
from ..scene import ManifestError
from ..scene.ground_truth import has_insertion_truth, has_lateral_truth, with_placements
from ..splat.constants import ALPHA_THRESHOLD
from .accuracy_time import Setting

DEFAULTS = StageOptions()


@dataclass
class Budget:
    """How much of the package each measurement uses (``--quick`` shrinks it)."""

    render_frames: int = 3  # held-out frames per renderer setting
    restore_frames: int = 2  # recorded frames whose lateral views are restored
    offsets: tuple[float, ...] = (1.0, 3.0)
    placements: int = 3  # held-out insertion placements
    reconstruct_iters: int = 1000  # iterations of each reconstruction setting


QUICK = Budget(render_frames=1, restore_frames=1, offsets=(3.0,), placements=1, reconstruct_iters=100)


def spread(items: list, n: int) -> list:
    """``n`` items evenly inside the list (the middle one for n = 1), away from its ends where a
    recorded sequence sees least."""
    if n >= len(items):
        return list(items)
    return [items[int((k + 1) * len(items) / (n + 1))] for k in range(n)]


def _mean_scores(pairs: list[tuple[np.ndarray, np.ndarray]]) -> dict:
    from ..metrics import psnr, ssim

    return {"psnr": float(np.mean([psnr(a, b) for a, b in pairs])),
            "ssim": float(np.mean([ssim(a, b) for a, b in pairs]))}


def renderer_settings(manifest, gaussians, budget: Budget) -> list[Setting]:
    """Each rasterizer option against Cycles on held-out frames (render time per frame)."""
    from ..conventions import scale_intrinsics
    from ..io.images import read_image
    from ..scene.ground_truth import split_frames
    from ..splat.render import params_from_gaussians, render_params

    cam = manifest.cameras[0]
    frames = spread(split_frames(manifest)[1], budget.render_frames)
    truth = {fi: read_image(manifest.resolve(cam.frames[fi].image), channels=3) for fi in frames}
    params = params_from_gaussians(gaussians, gaussians.sh_degree)
    params64 = {k: v.double() for k, v in params.items()}

    def measure(degree=gaussians.sh_degree, scale=1.0, dtype=torch.float32, **raster):
        p = params64 if dtype == torch.float64 else params

        @torch.no_grad()
        def one(fi: int) -> torch.Tensor:
            cf = cam.frames[fi]
            w, h = round(cam.width * scale), round(cam.height * scale)
            K = torch.tensor(scale_intrinsics(cf.K, w / cam.width, h / cam.height), dtype=dtype)
            rgb = render_params(p, K, torch.tensor(cf.world_to_camera, dtype=dtype), w, h, degree, **raster)[0]
            if (w, h) != (cam.width, cam.height):  # what a user gets by upsampling a cheap render
                rgb = torch.nn.functional.interpolate(rgb.permute(2, 0, 1)[None], size=(cam.height, cam.width),
                                                      mode="bilinear", align_corners=False)[0].permute(1, 2, 0)
            return rgb.clamp(0, 1).float()

        def run() -> dict:
            one(frames[0])  # untimed: compiles the kernels for this dtype and these options
            t0 = time.perf_counter()
            images = [one(fi).numpy() for fi in frames]
            seconds = (time.perf_counter() - t0) / len(frames)
            return {**_mean_scores([(img, truth[fi]) for img, fi in zip(images, frames)]), "seconds": seconds,
                    "per": "frame"}
        return run

    full = gaussians.sh_degree
    return [
        Setting("antialiasing", "off", True, measure(antialiased=False)),
        Setting("antialiasing", "on (Mip-Splatting 2D filter)", False, measure(antialiased=True)),
        Setting("extent", "opacity-aware", True, measure(extent="opacity")),
        Setting("extent", "3 sigma", False, measure(extent="3sigma")),
        Setting("extent", "2 sigma", False, measure(extent=2.0)),
        *[Setting("SH degree", str(d), d == full, measure(degree=d)) for d in range(full + 1)],
        *[Setting("alpha threshold", f"1/{round(1 / a)}", a == ALPHA_THRESHOLD,
                  measure(alpha_threshold=a)) for a in (1 / 1000, ALPHA_THRESHOLD, 1 / 64)],
        Setting("precision", "float32", True, measure()),
        Setting("precision", "float64", False, measure(dtype=torch.float64)),
        *[Setting("resolution", f"{s:g}x, upsampled", s == 1.0, measure(scale=s)) for s in (0.5, 0.75, 1.0)],
    ]


def lateral_quality(rows: list[dict]) -> dict:
    """Means of lateral rows' ``psnr``, ``ssim``, ``psnr_cc`` and ``lane_iou`` (IoU points), each
    where every row carries it (a package without lane masks has no lane IoU)."""
    return {k: float(np.mean([r[k] for r in rows])) for k in ("psnr", "ssim", "psnr_cc", "lane_iou")
            if rows and all(k in r for r in rows)}


def restorer_settings(manifest, gaussians, restorer, budget: Budget) -> list[Setting]:
    """Sampler steps, start noise and ``N_start`` on the pipeline's chain (the geometry-guided one
    where the package gives the warp a ground), and the auto-regressive step ``d`` of each chain."""
    from ..diffusion.restore import chain_warper
    from ..diffusion.warp import WarpError
    from ..eval.restoration import run_lateral_restoration
    from ..eval.views import evaluate_lateral
    from ..pipeline.stages import chain_method
    from ..scene.ground_truth import lateral_views, truth_camera, with_lateral_offsets

    scoped = with_lateral_offsets(manifest, budget.offsets)
    frames = spread(sorted({v.frame for v in lateral_views(scoped)}), budget.restore_frames)
    try:
        warper = chain_warper(scoped, truth_camera(scoped), gaussians)
    except WarpError:
        warper = None

    def raw() -> dict:  # the reference every restoration setting should beat
        t0 = time.perf_counter()
        rows = evaluate_lateral(scoped, gaussians, "raw_3dgs", frames)
        return {**lateral_quality(rows), "seconds": (time.perf_counter() - t0) / sum(r["frames"] for r in rows),
                "per": "view"}

    def measure(method: str, **sampler):
        config = replace(DEFAULTS.sampler, max_memory_gib=None, **sampler)

        def run() -> dict:
            t0 = time.perf_counter()
            res = run_lateral_restoration(scoped, gaussians, restorer, methods=(method,), frames=frames,
                                          sampler=config, progress=False, warper=warper)
            views = len(res.views.get(method, []))
            return {**lateral_quality(res.rows), "seconds": (time.perf_counter() - t0) / max(views, 1), "per": "view"}
        return run

    unguided, guided = chain_method(DEFAULTS, guided=False), chain_method(DEFAULTS, guided=True)
    d = guided if warper is not None else unguided  # the pipeline's chain on this package
    s, n, k = DEFAULTS.sampler.steps, DEFAULTS.sampler.n_start, DEFAULTS.sampler.samples
    t_start = 1.0 - n / s  # every sampler-steps setting starts at the default's noise level
    steps = dict.fromkeys((s, 10, 20, 50))
    noise = {"noise-free, one evaluation": {"noise_free": True}, "1 noisy sample": {"noise_free": False, "samples": 1},
             **{f"mean of {j} noisy samples": {"noise_free": False, "samples": j} for j in dict.fromkeys((4, k))}}

    def step_label(method: str) -> str:
        method = method.removeprefix("geo_")
        return "single view" if method == "single_view" else method.replace("ar_d", "") + " m"

    settings = [
        *[Setting("sampler steps", f"{j} (from step {round(j * (1 - t_start))})", j == s,
                  measure(d, steps=j, n_start=round(j * (1 - t_start)))) for j in steps],
        *[Setting("start noise", label, all(getattr(DEFAULTS.sampler, f) == v for f, v in kw.items()),
                  measure(d, **kw)) for label, kw in noise.items()],
        # the paper's protocol: 50 steps, one sample
        *[Setting("N_start of 50 steps, 1 sample", f"{j} (t = {1 - j / 50:.2f})", abs(j / 50 - n / s) < 1e-9,
                  measure(d, steps=50, n_start=j, samples=1, noise_free=False))
          for j in dict.fromkeys((0, 5, 10, 15, round(50 * n / s)))],
        Setting("AR step d", "no restoration (raw 3DGS)", False, raw),
        *[Setting("AR step d", step_label(m), m == unguided, measure(m))
          for m in dict.fromkeys(("single_view", "ar_d0.5", "ar_d1.0", "ar_d1.5", unguided))],
    ]
    if warper is not None:
        settings += [Setting("AR step d, guided", "warp alone (no restorer)", False, measure("warp")),
                     *[Setting("AR step d, guided", step_label(m), m == guided, measure(m))
                       for m in dict.fromkeys(("geo_single_view", "geo_ar_d0.5", "geo_ar_d1.0", guided))]]
    return settings


def finetune_settings(manifest, gaussians, restorer, budget: Budget) -> list[Setting]:
    """Colour/opacity fine-tune iterations, scored as masked PSNR of held-out placements."""

    from ..eval.insertion import evaluate_insertion
    from ..insertion.harmonizer import restorer_harmonizer

    harmonize = restorer_harmonizer(restorer, DEFAULTS.harmonize)
    cache: dict[bytes, np.ndarray] = {}

    def harmonizer(image, region):  # the same targets for every setting: harmonize once
        key = image.tobytes() + np.packbits(region).tobytes()
        if key not in cache:
            cache[key] = harmonize(image, region)
        return cache[key]

    scoped = with_placements(manifest, budget.placements)

    def measure(steps: int):
        def run() -> dict:
            details: dict = {}
            cfg = replace(DEFAULTS.insertion, finetune=replace(DEFAULTS.insertion.finetune, steps=max(steps, 1)))
            rows = evaluate_insertion(scoped, gaussians, harmonizer=harmonizer, config=cfg, details=details,
                                      progress=False)
            row = next(r for r in rows if r["method"] == ("finetuned" if steps else "naive"))
            seconds = float(np.mean(details["timings"]["finetune_seconds"])) if steps else 0.0
            return {"psnr": row["masked_psnr"], "ssim": row["masked_ssim"], "seconds": seconds, "per": "placement"}
        return run

    default = DEFAULTS.insertion.finetune.steps
    return [Setting("fine-tune iterations", str(k), k == default, measure(k))
            for k in dict.fromkeys((0, 50, 150, default, 600))]


def harmonize_settings(manifest, gaussians, restorer, budget: Budget) -> list[Setting]:
    """RePaint sampler steps (same start fraction), samples averaged and the context around the
    region the sampler sees, scored as masked PSNR of the harmonized frame against the car truly in
    the scene; seconds per harmonized frame."""

    from ..eval.insertion import evaluate_insertion
    from ..insertion.harmonizer import restorer_harmonizer

    scoped = with_placements(manifest, budget.placements)

    def measure(steps: int, samples: int, margin: int | None = CROP_MARGIN):
        def run() -> dict:
            details: dict = {}
            harmonizer = restorer_harmonizer(restorer, replace(DEFAULTS.harmonize, steps=steps, samples=samples),
                                             crop_margin=margin)
            cfg = replace(DEFAULTS.insertion, train_views=1, finetune=replace(DEFAULTS.insertion.finetune, steps=1))
            rows = evaluate_insertion(scoped, gaussians, harmonizer=harmonizer, config=cfg, details=details,
                                      progress=False)
            row = next(r for r in rows if r["method"] == "harmonized")
            return {"psnr": row["masked_psnr"], "ssim": row["masked_ssim"],
                    "seconds": float(np.mean(details["timings"]["harmonize_seconds"])), "per": "frame"}
        return run

    steps, samples = DEFAULTS.harmonize.steps, DEFAULTS.harmonize.samples
    return [*[Setting("harmonize steps", str(k), k == steps, measure(k, samples)) for k in dict.fromkeys((steps, 20, 50))],
            *[Setting("harmonize samples", str(k), k == samples, measure(steps, k)) for k in dict.fromkeys((1, samples, 8))],
            Setting("harmonize crop margin", "whole image", False, measure(steps, samples, None)),
            *[Setting("harmonize crop margin", f"{k} px", k == CROP_MARGIN, measure(steps, samples, k))
              for k in dict.fromkeys((16, CROP_MARGIN, 64))]]


def shadow_settings(manifest, gaussians, budget: Budget) -> list[Setting]:
    """The cast shadow off, and on at several shade ratios: masked PSNR of the naive insertion
    (car and shadow) against the car truly in the scene; seconds per inserted frame."""
    import time
    from dataclasses import replace

    from ..eval.insertion import scores, truth
    from ..insertion.assets import load_vehicle_asset
    from ..insertion.insert import insert_frame
    from ..insertion.placements import held_out_placements
    from ..splat.tensors import GaussianTensors

    background = GaussianTensors.from_gaussians(gaussians)
    placements = held_out_placements(manifest)[: budget.placements]
    cars = [load_vehicle_asset(manifest.resolve(p.asset)).gaussians for p in placements]

    def measure(ratio: float | None):
        scene = replace(manifest, effects=replace(manifest.effects, shadows=ratio is not None,
                                                  shadow_ratio=ratio))

        def run() -> dict:
            rows, seconds = [], []
            for p, car in zip(placements, cars):
                t = time.perf_counter()
                frame = insert_frame(scene, background, car, p.pose, p.wlh, p.camera)
                seconds.append(time.perf_counter() - t)
                rows.append(scores(frame.image, *truth(manifest, p)))
            return {"psnr": float(np.mean([r["masked_psnr"] for r in rows])),
                    "ssim": float(np.mean([r["masked_ssim"] for r in rows])), "seconds": float(np.mean(seconds)),
                    "per": "frame"}
        return run

    default = manifest.effects.shade
    return [Setting("cast shadow", "off", False, measure(None)),
            *[Setting("cast shadow", f"shade keeps {r:.2f}", abs(r - default) < 1e-9, measure(r))
              for r in sorted({0.2, 0.3, default, 0.5, 0.6})]]


def package_settings(manifest, quick: bool = False) -> tuple[list[Setting], dict[str, str]]:
    """Every knob the package's ground truth can score, and why the others are left out; a
    :class:`ManifestError` before any work when it can score none."""
    from ..diffusion.models import load_restorer
    from ..io.ply import read_splats
    from ..scene.ground_truth import missing_truth, split_frames

    budget = QUICK if quick else Budget()
    heldout = bool(split_frames(manifest)[1]) and all(f.image for f in manifest.cameras[0].frames)
    if not (heldout or has_lateral_truth(manifest) or has_insertion_truth(manifest)):
        raise missing_truth(manifest, None, "nothing to score: no held-out recorded images and no lateral or "
                            "insertion ground truth", "bench accuracy-time needs one of them")
    if not manifest.background_splats:
        raise ManifestError(manifest.path or manifest.root, "no background splats to measure", "background.splats")
    gaussians = read_splats(manifest.resolve(manifest.background_splats))
    lateral, insertion = has_lateral_truth(manifest), has_insertion_truth(manifest)
    settings, skipped = [], {}
    if heldout:
        settings += renderer_settings(manifest, gaussians, budget)
    else:
        skipped["renderer"] = "no held-out recorded frames"
    if heldout and manifest.background_points:
        from .reconstruction import reconstruction_settings

        settings += reconstruction_settings(manifest, budget.reconstruct_iters)
    else:
        skipped["reconstruction"] = "no held-out recorded frames" if not heldout else "no point cloud to start from"
    restorer = load_restorer() if lateral or insertion else None
    if lateral:
        settings += restorer_settings(manifest, gaussians, restorer, budget)
    else:
        skipped["restorer"] = "no lateral ground truth"
    if insertion and manifest.effects.sun_direction is not None:
        settings += shadow_settings(manifest, gaussians, budget)
    if insertion:
        settings += harmonize_settings(manifest, gaussians, restorer, budget)
        settings += finetune_settings(manifest, gaussians, restorer, budget)
    else:
        skipped["fine-tune"] = "no insertion ground truth"
    return settings, skipped


WHY_DEFAULTS = {
    "antialiasing": "off: the shipped reconstruction was trained without the 2D filter and a render should match "
                    "its training; turn it on for scenes trained with it or rendered far below training resolution.",
    "extent": "opacity-aware: a footprint ends where alpha falls below the threshold, so faint Gaussians cover "
              "fewer tiles; a fixed 2 sigma cuts tails that still show.",
    "SH degree": "the asset's full degree: a lower one drops view-dependent colour (paint, glass), which a scene "
                 "with little of it, like the demo street, does not show.",
    "alpha threshold": "1/255, the 3DGS value: a smaller contribution does not show in an 8-bit image.",
    "precision": "float32: float64 gives the same image to within 8-bit quantisation at twice the memory.",
    "resolution": "full: rendering small and upsampling blurs edges that the metric and the restorer see.",
    "sampler steps": f"{DEFAULTS.sampler.steps} steps from step {DEFAULTS.sampler.n_start} (one Euler step from t = 0.2): the "
                     "shipped small restorer's errors add up along the Euler path, so the fewest steps from a low "
                     "noise level measure best.",
    "start noise": "noise-free: one evaluation from the start without noise scores as the mean of 8 noisy "
                   "samples does (which cancels each sample's grain: one noisy sample, the paper's, keeps it), "
                   "for an eighth of the work.",
    "N_start of 50 steps, 1 sample": "the shipped small restorer keeps the render's structure best when it starts "
                                     "low on the noise scale (Flux in the paper starts at 10 of 50).",
    "AR step d": f"{DEFAULTS.ar_step:g} m, the paper's method: each view is restored from a restored neighbour "
                 "and a render on its other side, which measures above the single-view ablation; 1 m chains half "
                 "the restorations for the same PSNR but loses lane IoU at 1 m.",
    "AR step d, guided": f"{DEFAULTS.guided_ar_step:g} m: the guided chain scores at least as well as at 0.5 m with "
                         "half the restorations, and above the warp it starts from.",
    "cast shadow": "on, at the scene's effects.shadow_ratio (0.4 when the scene gives none): a car "
                   "without its shadow floats; how dark shade is depends on the sky, so the table shows the "
                   "cost of a wrong ratio.",
    "harmonize steps": f"{DEFAULTS.harmonize.steps}, started {DEFAULTS.harmonize.start_fraction:g} of the way down "
                       "(t = 0.8: the vehicle needs a high noise level to change its lighting); the paper's 50 "
                       "steps measure worse with the shipped restorer, whose errors add up per step.",
    "harmonize samples": f"{DEFAULTS.harmonize.samples}: the mean of harmonizations cancels most of the small "
                         "restorer's grain; 8 gains little more for twice the time.",
    "harmonize crop margin": f"{CROP_MARGIN} px of context around the region: from 16 to 64 px the masked PSNR "
                             "stays within 0.1 dB of the whole image's at a fraction of its time; 16 px is "
                             "faster still but leaves the network less of the scene around the vehicle.",
    "fine-tune iterations": f"{DEFAULTS.insertion.finetune.steps}: past it the masked PSNR stops rising while time grows "
                            "linearly.",
    "resolution schedule": "full resolution throughout: coarse to fine trains its first iterations on cheaper "
                           "images but ended below the full-resolution fit on both Cycles streets, without reaching "
                           "its held-out PSNR (docs/results.md); `--resolution-schedule` keeps it at hand for larger "
                           "images, whose iterations it cheapens more.",
    "densify until": "the config's share of the iterations, 3DGS's schedule scaled to these runs; the rows show "
                     "what an earlier end saves and costs.",
}
