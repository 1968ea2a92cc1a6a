"""``symdrive demo``: the built-in street world end to end, with a short illustrated report.

Runs the planner and every stage on the shipped Cycles world (render, restore the lateral
views, harmonize and fine-tune the inserted vehicles, evaluate against Cycles), then drives the
fine-tuned vehicle along the road and re-renders it, and writes ``report.md`` with figures.
``--quick`` uses fewer frames and sampler steps (and no 3DGS refinement) to finish in minutes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..diffusion.config import RefineConfig
from ..insertion.config import InsertionConfig
from ..optim.config import FinetuneConfig
from ..pipeline.lock import OutputLock
from ..pipeline.outputs import OutputTree
from ..pipeline.plan import PlanOptions
from ..pipeline.stages import StageOptions

DEMO_PACKAGE = Path(__file__).resolve().parent.parent / "data" / "demo_street"

# The demo's window: frames with lateral truth, and in the quick run the right side at 1 and 3 m.
QUICK = (PlanOptions(refine=False, frames=[12], offsets=(1.0, 3.0)),
         StageOptions(eval_methods=("single_view", "ar_d0.5"),
                      insertion=InsertionConfig(train_views=2, finetune=FinetuneConfig(steps=80))))
FULL = (PlanOptions(frames=[2, 12, 22]), StageOptions(refine=RefineConfig(iters=300)))


def road_trajectory(manifest, height_m: float, start_m: float = 8.0, speed_mps: float | None = None,
                    lane_right_m: float = 1.75) -> list:
    """One pose per frame driving along the world's road, ``lane_right_m`` right of its centre
    line (the ego lane), starting ``start_m`` ahead of the first camera, heading along the road.
    The default speed is 1.1 times the recording camera's, so the car pulls slowly away from it."""
    from ..rotations import quat_from_yaw
    from ..scene.poses import Pose
    from ..scene.road import road_from_json

    if speed_mps is None:
        centres = [f.camera_to_world[:3, 3] for f in manifest.cameras[0].frames]
        duration = manifest.frames[-1].timestamp - manifest.frames[0].timestamp
        path = float(np.sum(np.linalg.norm(np.diff(centres, axis=0), axis=1)))
        speed_mps = 1.1 * path / duration if duration > 0 else 0.0
    line = road_from_json(manifest.ground_truth["road"], manifest.path).centerline
    seg = np.linalg.norm(np.diff(line[:, :2], axis=0), axis=1)
    along = np.concatenate([[0.0], np.cumsum(seg)])
    cam0 = manifest.cameras[0].frames[0].camera_to_world[:3, 3]
    s0 = along[int(np.argmin(np.linalg.norm(line[:, :2] - cam0[:2], axis=1)))] + start_m
    t0 = manifest.frames[0].timestamp
    poses = []
    for f in manifest.frames:
        s = s0 + speed_mps * (f.timestamp - t0)
        i = int(np.clip(np.searchsorted(along, s) - 1, 0, len(seg) - 1))
        u = (s - along[i]) / seg[i]
        centre = (1 - u) * line[i] + u * line[i + 1]
        d = (line[i + 1, :2] - line[i, :2]) / seg[i]
        right = np.array([d[1], -d[0]])
        xy = centre[:2] + lane_right_m * right
        poses.append(Pose(np.array([xy[0], xy[1], centre[2] + height_m / 2.0]),
                          quat_from_yaw(float(np.arctan2(d[1], d[0])))))
    return poses


def _montage(path: Path, panels: list[tuple[str, np.ndarray]], columns: int | None = None) -> Path:
    """Labelled images side by side (PNG via matplotlib)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io.atomic import atomic_path

    columns = columns or len(panels)
    rows = (len(panels) + columns - 1) // columns
    h, w = panels[0][1].shape[:2]
    fig, axes = plt.subplots(rows, columns, figsize=(columns * w / 80, rows * (h / 80 + 0.3)), squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for ax, (title, img) in zip(axes.ravel(), panels):
        ax.imshow(np.clip(img, 0, 1))
        ax.set_title(title, fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=80)
    plt.close(fig)
    return path


def _lateral_plot(path: Path, rows: list[dict]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io.atomic import atomic_path

    fig, ax = plt.subplots(figsize=(5, 3.2))
    for method in dict.fromkeys(r["method"] for r in rows):
        pts = sorted((r["offset_m"], r["psnr"]) for r in rows if r["method"] == method)
        ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", label=method, ms=4)
    ax.set_xlabel("lateral offset (m)")
    ax.set_ylabel("PSNR vs Cycles (dB)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
    return path


def render_trajectory(manifest, background, vehicle, wlh, out_dir: Path, progress: bool = True) -> list[Path]:
    """Drive ``vehicle`` along the road in front of the recorded camera and render every frame
    (with its cast shadow where the scene has a sun)."""
    from tqdm import tqdm

    from ..insertion.insert import insert_frame
    from ..io.images import write_image
    from ..scene.camera import CameraView

    cam = manifest.cameras[0]
    paths = []
    for fi, pose in enumerate(tqdm(road_trajectory(manifest, float(wlh[2])), desc="trajectory", unit="frame",
                                   disable=not progress)):
        frame = insert_frame(manifest, background, vehicle, pose, wlh, CameraView.of_frame(cam, fi))
        paths.append(write_image(out_dir / f"{fi:06d}.png", frame.image))
    return paths


def run_demo(out: str | Path, quick: bool = False, progress: bool = True, force: bool = False) -> dict:
    """Run the demo; returns the report (also written to ``out/report.json`` and ``report.md``)."""
    tree = OutputTree(out)
    with OutputLock(tree.root):  # the figures and report.md too are this run's
        return _run_demo(tree, QUICK if quick else FULL, quick, progress, force)


def _run_demo(tree: OutputTree, options: tuple[PlanOptions, StageOptions], quick: bool, progress: bool,
              force: bool) -> dict:
    import time

    from ..insertion.assets import load_vehicle_asset
    from ..insertion.placements import held_out_placements
    from ..io.atomic import write_text_atomic
    from ..io.images import read_image
    from ..io.ply import read_splats
    from ..pipeline.outputs import REPORT
    from ..pipeline.report import write_report_json
    from ..pipeline.run import run_scene
    from ..scene import load_manifest
    from ..scene.ground_truth import lateral_views
    from ..splat.render import SplatRenderer
    from ..splat.tensors import GaussianTensors

    out = tree.root
    t0 = time.perf_counter()
    plan_options, stage_options = options
    report = run_scene(DEMO_PACKAGE, out, options=plan_options, stage_options=stage_options,
                       progress=progress, force=force, lock=False)
    manifest = load_manifest(DEMO_PACKAGE)
    background = read_splats(manifest.resolve(manifest.background_splats))
    figures = tree.folder("figures")
    fi = plan_options.frames[0]

    lateral = [v for v in lateral_views(manifest) if v.frame == fi and abs(v.offset_m) == 3.0 and v.offset_m > 0]
    if lateral:
        v = lateral[0]
        restored = tree.frame("restore", f"{manifest.cameras[0].name}/{v.offset_m:+g}", fi)
        panels = [("recorded view (0 m)", read_image(manifest.resolve(manifest.cameras[0].frames[fi].image), channels=3)),
                  ("raw 3DGS at +3 m", SplatRenderer(background)(v.camera)),
                  ("restored at +3 m", read_image(restored, channels=3)),
                  ("Cycles at +3 m", read_image(manifest.resolve(v.image), channels=3))]
        _montage(figures / "lateral.png", panels)
    if report["metrics"].get("lateral"):
        _lateral_plot(figures / "lateral_psnr.png", report["metrics"]["lateral"])

    placements = held_out_placements(manifest)
    finetuned = sorted((out / "insertion_assets").glob("*.ply"))
    if placements and finetuned:
        from ..insertion.insert import insert_frame, render_insertion

        p = placements[0]
        bg_t = GaussianTensors.from_gaussians(background)
        asset = load_vehicle_asset(manifest.resolve(p.asset))
        panels = [("naive insertion", render_insertion(p.camera, bg_t, asset.gaussians, p.pose)[0])]
        harmonized = tree.frame("harmonize", p.camera_name, p.frame)
        if harmonized.exists():
            panels.append(("harmonized (RePaint)", read_image(harmonized, channels=3)))
        tuned_asset = read_splats(finetuned[0])
        tuned = insert_frame(manifest, bg_t, tuned_asset, p.pose, p.wlh, p.camera)
        panels += [("fine-tuned asset" + (" + shadow" if tuned.shadow is not None else ""), tuned.image),
                   ("Cycles, car truly in scene", read_image(manifest.resolve(p.with_image), channels=3))]
        _montage(figures / "insertion.png", panels)
        paths = render_trajectory(manifest, bg_t, tuned_asset, p.wlh, tree.folder("trajectory"), progress)
        picks = paths[:: max(1, len(paths) // 4)][:4]
        _montage(figures / "trajectory.png", [(f"frame {int(q.stem)}", read_image(q, channels=3)) for q in picks])
    report["demo_seconds"] = round(time.perf_counter() - t0, 1)
    report["demo_mode"] = "quick" if quick else "full"
    write_report_json(tree.path(REPORT), report)
    write_text_atomic(tree.path("report.md"), format_markdown(report, figures))
    return report


def format_markdown(report: dict, figures: Path) -> str:
    lines = [f"# SymDrive demo: {report['scene']} ({report['demo_mode']})", "",
             f"Device {report['device']}; {report['demo_seconds']} s in all. Every number below was "
             "measured in this run against Cycles renders of the same cameras.", "", "## Stages", "",
             "| stage | ran | why | seconds | did |", "|---|---|---|---|---|"]
    for s in report["stages"]:
        did = ", ".join(f"{k.replace('_', ' ')}: {v}" for k, v in s.items()
                        if k not in ("name", "ran", "reason", "seconds") and not isinstance(v, (list, dict)))
        lines.append(f"| {s['name']} | {'yes' if s['ran'] else 'no'} | {s['reason']} | {s.get('seconds', '')} | {did} |")
    rec = report["metrics"].get("reconstruction")
    if rec:
        lines += ["", "## Reconstruction (held-out frames)", "",
                  f"PSNR {rec['psnr_heldout']:.2f} dB, SSIM {rec['ssim_heldout']:.3f} over {rec['frames']} frames."]
    if report["metrics"].get("lateral"):
        lines += ["", "## Lateral novel views", "",
                  "| offset (m) | method | PSNR | PSNR-cc | SSIM | lane IoU (ceiling) |", "|---|---|---|---|---|---|"]
        for r in report["metrics"]["lateral"]:
            lane = f"{r['lane_iou']:.1f} ({r['lane_iou_ceiling']:.1f})" if "lane_iou" in r else ""
            cc = f"{r['psnr_cc']:.2f}" if "psnr_cc" in r else ""  # rows an older run stored lack it
            lines.append(f"| {r['offset_m']:+g} | {r['method']} | {r['psnr']:.2f} | {cc} | {r['ssim']:.3f} | {lane} |")
        lines += ["", "![lateral PSNR](figures/lateral_psnr.png)", "", "![lateral views](figures/lateral.png)"]
    if report["metrics"].get("insertion"):
        lines += ["", "## Vehicle insertion (held-out placements)", "",
                  "| method | masked PSNR | masked SSIM | PSNR |", "|---|---|---|---|"]
        for r in report["metrics"]["insertion"]:
            lines.append(f"| {r['method']} | {r['masked_psnr']:.2f} | {r['masked_ssim']:.3f} | {r['psnr']:.2f} |")
        lines += ["", "![insertion](figures/insertion.png)", "", "## Fine-tuned vehicle on a new trajectory", "",
                  "![trajectory](figures/trajectory.png)"]
    return "\n".join(lines) + "\n"
