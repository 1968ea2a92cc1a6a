"""What reconstruction accuracy costs in time: held-out PSNR / SSIM against training seconds, for
several reconstruction schedules fitted side by side in one process.

The fits advance in turns of ``every`` iterations, so a machine that slows down for a while slows
every schedule alike, and each is scored on the package's held-out frames between its turns; the
seconds are the training alone (scoring excluded). From the curves: how long each schedule takes
to reach the held-out PSNR the default schedule ends at, as a ratio of the default's whole time.
Schedules that differ only in the fraction pruned (``importance_prune``) are one fit until the
prune, so they share it to there.
"""

from __future__ import annotations

import copy
import csv
import json
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_path, write_text_atomic
from ..optim.config import COARSE_TO_FINE, DensifyConfig, ReconstructConfig

# Schedules measured against each other (overrides of ReconstructConfig); whichever equals the
# config's defaults as they resolve for the package's images is the default.
SCHEDULES = {
    "full resolution": {"resolution_schedule": ()},
    "coarse to fine": {"resolution_schedule": COARSE_TO_FINE},
    # densification's cap halved: a real drive reaches the default's 200k by 60 % of the iterations
    "coarse to fine, 100k Gaussians": {"resolution_schedule": COARSE_TO_FINE,
                                       "densify": DensifyConfig(max_gaussians=100_000)},
    # the 60 % of each part's Gaussians that paint the least removed when densification ends
    "coarse to fine, pruned 0.6": {"resolution_schedule": COARSE_TO_FINE, "importance_prune": 0.6},
    "full resolution, pruned 0.6": {"resolution_schedule": (), "importance_prune": 0.6},
}


def schedule_configs(iters: int | None = None, schedules: dict[str, dict] | None = None) -> dict[str, ReconstructConfig]:
    """Each schedule's config (``iters`` replaces the default iteration count of every one)."""
    base = ReconstructConfig() if iters is None else ReconstructConfig(iters=iters)
    return {name: replace(base, **over) for name, over in (schedules or SCHEDULES).items()}


def training_pixels(manifest) -> int:
    """The pixels of the package's largest training image (what the default schedule depends on)."""
    from ..optim.views import training_cameras

    return max(c.width * c.height for c in training_cameras(manifest))


def default_config(iters: int, pixels: int) -> ReconstructConfig:
    """The defaults at ``iters`` iterations, their resolution schedule as it resolves for images
    of ``pixels`` pixels."""
    d = ReconstructConfig(iters=iters)
    return replace(d, resolution_schedule=d.schedule_for(pixels))


def default_name(configs: dict[str, ReconstructConfig], pixels: int) -> str:
    """The schedule whose config is the defaults for images of ``pixels`` pixels (at its iteration
    count); else the first."""
    return next((n for n, c in configs.items() if c == default_config(c.iters, pixels)), next(iter(configs)))


def heldout_scores(manifest, fit) -> dict:
    """``eval.views.evaluate_heldout`` of a :class:`~symdrive_core.optim.reconstruct.Fit` as it
    stands, scored as ``symdrive reconstruct`` scores its end: the vehicles and cameras where the fit
    placed them, each camera through its colour transform. ``manifest`` stays as recorded (a copy
    is placed)."""
    from ..eval.views import evaluate_heldout
    from ..optim.reconstruct import with_fitted

    placed = with_fitted(copy.deepcopy(manifest), fit.poses(), fit.camera_poses(manifest))
    g, actors = fit.gaussians()
    return evaluate_heldout(placed, g, fit.heldout_frames, actors=actors, shadows=fit.layers(),
                            exposure=None if fit.exposure is None else fit.exposure.by_camera())


def curves(manifest, configs: dict[str, ReconstructConfig], every: int, progress: bool = True) -> list[dict]:
    """Rows (schedule, iteration, seconds of training so far, psnr, ssim, gaussians), each schedule
    scored at iteration 0 and every ``every`` iterations to its end."""
    from tqdm import tqdm

    from ..optim.reconstruct import Fit

    # Schedules that differ only in the fraction pruned are the same fit until the prune: one trunk
    # fit trains to the last scoring before it (standing in for each), then each gets a copy.
    trunks: dict[str, list[str]] = {}
    for name, cfg in configs.items():
        trunks.setdefault(repr(replace(cfg, importance_prune=0.0)), []).append(name)
    branches = {names[0]: (names, max(0, (configs[names[0]].densify_end - 1) // every * every))
                for names in trunks.values() if len(names) > 1}
    fits = {name: Fit.start(manifest, configs[name]) for names in trunks.values() for name in names[:1]}
    seconds = dict.fromkeys(fits, 0.0)
    rows = []

    def score(name: str, fit: Fit) -> None:
        q = heldout_scores(manifest, fit)
        rows.append({"schedule": name, "iteration": fit.iteration, "seconds": round(seconds[name], 3),
                     "psnr": q["psnr_heldout"], "ssim": q["ssim_heldout"],
                     "gaussians": sum(len(p.params["means"]) for p in fit.parts)})

    def branch(names: list[str], trunk: Fit) -> None:
        """The trunk's rows and state for each of ``names`` (the first keeps the trunk itself)."""
        mine = [r for r in rows if r["schedule"] == names[0]]
        for name in names[1:]:
            fits[name] = copy.deepcopy(trunk)
            seconds[name] = seconds[names[0]]
            rows.extend(dict(r, schedule=name) for r in mine)
        for name in names:
            fits[name].cfg = replace(trunk.cfg, importance_prune=configs[name].importance_prune)

    for name, fit in fits.items():
        score(name, fit)
    bar = tqdm(total=sum(c.iters for c in configs.values()), desc="bench reconstruct", unit="it", disable=not progress)
    while any(f.iteration < f.cfg.iters for f in fits.values()):
        for name, fit in list(fits.items()):
            if name in branches and fit.iteration == branches[name][1]:
                branch(branches.pop(name)[0], fit)
        for name, fit in fits.items():
            if fit.iteration < fit.cfg.iters:
                before = fit.iteration
                step = min(every, branches[name][1] - before) if name in branches else every
                seconds[name] += fit.train(until=before + step, progress=False)["seconds"]
                bar.update((fit.iteration - before) * (len(branches[name][0]) if name in branches else 1))
                score(name, fit)
    bar.close()
    return rows


def seconds_to_reach(rows: list[dict], schedule: str, psnr: float) -> float | None:
    """Training seconds at the first scoring where ``schedule`` reached ``psnr``; None if never."""
    return next((r["seconds"] for r in rows if r["schedule"] == schedule and r["psnr"] >= psnr), None)


def summary(rows: list[dict], default: str) -> dict:
    """Per schedule: final PSNR / SSIM, seconds, and seconds to reach the default's final PSNR,
    also as a ratio of the default's whole time."""
    last = {r["schedule"]: r for r in rows}  # rows run in order: the last of each is its end
    target, total = last[default]["psnr"], last[default]["seconds"]
    out = {"default": default, "target_psnr": target, "schedules": {}}
    for name, r in last.items():
        reach = seconds_to_reach(rows, name, target)
        out["schedules"][name] = {"iterations": r["iteration"], "psnr": r["psnr"], "ssim": r["ssim"],
                                  "seconds": r["seconds"], "gaussians": r["gaussians"], "seconds_to_target": reach,
                                  "time_ratio": None if reach is None else round(reach / total, 3)}
    return out


def format_summary(s: dict) -> str:
    lines = [f"held-out PSNR the default ({s['default']}) ends at: {s['target_psnr']:.2f} dB",
             "| schedule | iterations | final PSNR (dB) | SSIM | seconds | seconds to the default's PSNR | "
             "ratio to the default's time |", "|---|---|---|---|---|---|---|"]
    for name, r in s["schedules"].items():
        reach = "never" if r["seconds_to_target"] is None else f"{r['seconds_to_target']:.0f}"
        ratio = "" if r["time_ratio"] is None else f"{r['time_ratio']:.2f}"
        lines.append(f"| {name} | {r['iterations']} | {r['psnr']:.2f} | {r['ssim']:.4f} | {r['seconds']:.0f} | "
                     f"{reach} | {ratio} |")
    return "\n".join(lines)


def write_outputs(rows: list[dict], s: dict, configs: dict[str, ReconstructConfig], out_dir: str | Path,
                  title: str) -> dict[str, Path]:
    """curves.csv, summary.json (with each schedule's config) and curves.png (PSNR and SSIM
    against seconds, the default's final PSNR dashed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    with atomic_path(out / "curves.csv") as tmp, open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    write_text_atomic(out / "summary.json", json.dumps(
        {**s, "configs": {n: asdict(c) for n, c in configs.items()}}, indent=1) + "\n")
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for name in dict.fromkeys(r["schedule"] for r in rows):
        mine = [r for r in rows if r["schedule"] == name]
        label = f"{name} (default)" if name == s["default"] else name
        for ax, key in zip(axes, ("psnr", "ssim")):
            ax.plot([r["seconds"] for r in mine], [r[key] for r in mine], ".-", label=label)
    axes[0].axhline(s["target_psnr"], color="0.5", ls="--", lw=1)
    for ax, key in zip(axes, ("held-out PSNR (dB)", "held-out SSIM")):
        ax.set_xlabel("training seconds (scoring excluded)")
        ax.set_ylabel(key)
        ax.grid(alpha=0.3)
    axes[0].set_ylim(bottom=float(np.percentile([r["psnr"] for r in rows], 5)))
    axes[1].set_ylim(bottom=float(np.percentile([r["ssim"] for r in rows], 5)))
    axes[0].legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    with atomic_path(out / "curves.png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
    return {"csv": out / "curves.csv", "json": out / "summary.json", "png": out / "curves.png"}


def reconstruction_settings(manifest, iters: int) -> list:
    """``bench accuracy-time`` rows: whole reconstructions at ``iters`` iterations (the bench's
    budget; the config's default takes longer, and :func:`curves` gives PSNR at every iteration
    count), each schedule of :data:`SCHEDULES` and an earlier end of densification, each scored on
    the held-out frames; seconds per run, training alone. A setting the rows share is fitted once."""
    from ..optim.reconstruct import Fit
    from .accuracy_time import Setting

    pixels = training_pixels(manifest)
    default, base = default_config(ReconstructConfig().iters, pixels), default_config(iters, pixels)
    done: dict[str, dict] = {}

    def measure(cfg: ReconstructConfig):
        def run() -> dict:
            key = repr(cfg)
            if key not in done:
                fit = Fit.start(manifest, cfg)
                seconds = fit.train(progress=False)["seconds"]
                q = heldout_scores(manifest, fit)
                done[key] = {"psnr": q["psnr_heldout"], "ssim": q["ssim_heldout"], "seconds": seconds, "per": "run"}
            return dict(done[key])
        return run

    return [
        *[Setting("resolution schedule", name, over["resolution_schedule"] == default.resolution_schedule,
                  measure(replace(base, **over))) for name, over in SCHEDULES.items() if set(over) == {"resolution_schedule"}],
        *[Setting("densify until", f"{f:g} of the iterations", f == default.densify_until_fraction,
                  measure(replace(base, densify_until_fraction=f)))
          for f in dict.fromkeys((0.3, default.densify_until_fraction))],
    ]
