"""``symdrive run``: execute a scene's plan, resumably, and write outputs + report.json.

Outputs (under ``--out``): ``render/<camera>/<frame>.png`` (RGB), ``.depth.exr``,
``masks/<camera>/<actor>/<frame>.png`` (accumulated alpha per actor), ``report.json``,
``state.json``. Every file is written to a temporary name and renamed, so a killed run leaves
only complete files, and a re-run skips the frames whose outputs exist.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from ..io.images import read_image, write_image, write_mask
from ..scene import Manifest, check_files, load_manifest
from .plan import Plan, PlanOptions, make_plan
from .report import Report
from .state import RunState

STAGE_DIRS = ["render", "masks"]


@dataclass
class RunContext:
    manifest: Manifest
    plan: Plan
    out: Path
    state: RunState
    report: Report
    device: str
    progress: bool

    def frame_path(self, kind: str, camera: str, frame: int, suffix: str = ".png", actor: str | None = None) -> Path:
        return output_path(self.out, kind, camera, frame, suffix, actor)


def output_path(out: Path, kind: str, camera: str, frame: int, suffix: str = ".png", actor: str | None = None) -> Path:
    parts = [kind, camera] + ([actor] if actor else [])
    return Path(out).joinpath(*parts, f"{frame:06d}{suffix}")


def render_frames(manifest: Manifest, plan: Plan, out: Path, jobs: list[tuple[str, int]], device: str,
                  progress: bool = True) -> int:
    """Render (camera, frame) jobs whose outputs are missing; returns how many were rendered."""
    from .scene_render import SceneRenderer

    renderer = None
    done = 0
    for cam, fi in tqdm(jobs, desc="render", unit="frame", disable=not progress):
        rgb_path = output_path(out, "render", cam, fi)
        if rgb_path.exists():
            continue
        if renderer is None:
            renderer = SceneRenderer(manifest, device=device)
        frame = renderer.render(cam, fi, plan.visible[cam][fi])
        for actor_id, mask in frame.instance.items():
            write_mask(output_path(out, "masks", cam, fi, actor=actor_id), mask)
        write_image(output_path(out, "render", cam, fi, ".depth.exr"), frame.depth, dtype="float")
        write_image(rgb_path, frame.rgb)  # written last: its presence marks the frame complete
        done += 1
    return done


def _render_stage(ctx: RunContext) -> dict:
    jobs = [(cam.name, fi) for cam in ctx.manifest.cameras for fi in range(len(cam.frames))]
    done = render_frames(ctx.manifest, ctx.plan, ctx.out, jobs, ctx.device, ctx.progress)
    return {"frames_rendered": done, "frames_reused": len(jobs) - done}


def _evaluate_stage(ctx: RunContext) -> dict:
    from ..metrics import psnr, ssim

    heldout = set(ctx.manifest.ground_truth.get("heldout_frames", []))
    rows = []
    for cam in ctx.manifest.cameras:
        for fi, cf in enumerate(cam.frames):
            if cf.image is None or (heldout and fi not in heldout):
                continue
            gt = read_image(ctx.manifest.resolve(cf.image), channels=3)
            pred = read_image(ctx.frame_path("render", cam.name, fi), channels=3)
            rows.append((psnr(pred, gt), ssim(pred, gt)))
    if rows:
        key = "psnr_heldout" if heldout else "psnr"
        ctx.report.metrics["reconstruction"] = {
            key: round(sum(r[0] for r in rows) / len(rows), 3),
            key.replace("psnr", "ssim"): round(sum(r[1] for r in rows) / len(rows), 4),
            "frames": len(rows)}
    return {"frames_evaluated": len(rows)}


STAGE_RUNNERS = {"render": _render_stage, "evaluate": _evaluate_stage}
# Sub-effects decided by the planner and applied inside other stages (no runner of their own).
APPLIED_INSIDE = {"shadow_region": "harmonize", "sh_eval": "render"}


def run_scene(package, out_dir=None, *, options: PlanOptions | None = None, device: str = "cpu",
              progress: bool = True) -> dict:
    manifest = load_manifest(package)
    check_files(manifest)
    out = Path(out_dir) if out_dir is not None else manifest.root / manifest.output
    out.mkdir(parents=True, exist_ok=True)
    plan = make_plan(manifest, options, previous=RunState.load_raw(out))
    state = RunState.open(out, plan.inputs_hash, STAGE_DIRS)
    report = Report(manifest.name, device)
    ctx = RunContext(manifest, plan, out, state, report, device, progress)
    for decision in plan.stages:
        name = decision.name
        if not decision.run:
            report.stage(name, False, decision.reason)
        elif name in APPLIED_INSIDE:
            report.stage(name, True, f"{decision.reason} (applied in {APPLIED_INSIDE[name]})")
        elif name not in STAGE_RUNNERS:
            report.stage(name, False, f"{decision.reason}; this stage is not available in `symdrive run` yet")
        elif decision.cached:
            report.stage(name, False, decision.reason, state.seconds.get(name))
        else:
            t0 = time.perf_counter()
            details = STAGE_RUNNERS[name](ctx) or {}
            dt = time.perf_counter() - t0
            state.finish(name, dt)
            report.stage(name, True, decision.reason, dt, **details)
    report.write(out)
    return report.to_json()
