"""``symdrive run``: execute a scene's plan, resumably, and write outputs + report.json.

Outputs (under ``--out``): ``render/<camera>/<frame>.png`` (RGB), ``.depth.exr``,
``masks/<camera>/<actor>/<frame>.png`` (accumulated alpha per actor), ``report.json``,
``state.json``. Every file is written to a temporary name and renamed, so a killed run leaves
only complete files, and a re-run skips the frames whose outputs exist.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from ..io.images import write_image, write_mask
from ..scene import Manifest, check_files, load_manifest
from . import stages
from .cache_key import inputs_key
from .lock import OutputLock
from .outputs import ASSET_CACHE, OutputTree
from .plan import APPLIED_INSIDE, Plan, PlanOptions, make_plan
from .report import Report
from .stages import Shared, StageOptions
from .state import RunState


@dataclass
class RunContext:
    manifest: Manifest
    plan: Plan
    tree: OutputTree
    state: RunState
    report: Report
    device: str
    progress: bool
    options: StageOptions
    shared: Shared


def render_frames(manifest: Manifest, plan: Plan, out: Path | OutputTree, jobs: list[tuple[str, int]], device: str,
                  progress: bool = True) -> int:
    """Render (camera, frame) jobs whose outputs are missing; returns how many were rendered."""
    from .scene_render import SceneRenderer

    out = out if isinstance(out, OutputTree) else OutputTree(out)
    renderer = None
    done = 0
    casting = plan.stage("cast_shadow")
    for cam, fi in tqdm(jobs, desc="render", unit="frame", disable=not progress):
        rgb_path = out.frame("render", cam, fi)
        if rgb_path.exists():
            continue
        if renderer is None:
            renderer = SceneRenderer(manifest, device=device, asset_cache=out.folder(ASSET_CACHE))
        frame = renderer.render(cam, fi, plan.visible[cam][fi])
        if casting.run and fi in casting.frames:
            casters = [a for a in plan.visible[cam][fi] if a in casting.actors]
            frame = renderer.cast_shadows(cam, fi, frame, casters, manifest.effects.sun_direction,
                                          manifest.effects.shade)
        for actor_id, mask in frame.instance.items():
            write_mask(out.frame("masks", cam, fi, actor=actor_id), mask)
        if frame.shadow is not None:
            write_mask(out.frame("shadows", cam, fi), frame.shadow)
        write_image(out.frame("render", cam, fi, ".depth.exr"), frame.depth, dtype="float")
        write_image(rgb_path, frame.rgb)  # written last: its presence marks the frame complete
        done += 1
    return done


def _render_stage(ctx: RunContext) -> dict:
    jobs = [(cam.name, fi) for cam in ctx.manifest.cameras for fi in range(len(cam.frames))]
    done = render_frames(ctx.manifest, ctx.plan, ctx.tree, jobs, ctx.device, ctx.progress)
    return {"frames_rendered": done, "frames_reused": len(jobs) - done}


STAGE_RUNNERS = {"reconstruct": stages.reconstruct_stage, "render": _render_stage, "restore": stages.restore_stage,
                 "refine": stages.refine_stage, "harmonize": stages.harmonize_stage,
                 "finetune": stages.finetune_stage, "evaluate": stages.evaluate_stage}


def run_scene(package, out_dir=None, *, options: PlanOptions | None = None, device: str = "cpu",
              progress: bool = True, stage_options: StageOptions | None = None, force: bool = False,
              allow_external: bool = False, lock: bool = True) -> dict:
    """Run a package's plan into ``out_dir`` (default: the manifest's ``output``, inside the
    package). ``force`` runs beside files no run wrote there; ``lock=False`` is for a caller
    that already holds the folder's lock (a batch driver)."""
    manifest = load_manifest(package, allow_external=allow_external)
    check_files(manifest)
    options, stage_options = options or PlanOptions(), stage_options or StageOptions()
    tree = OutputTree(Path(out_dir) if out_dir is not None else manifest.output_dir())
    with OutputLock(tree.root) if lock else contextlib.nullcontext():
        state, plan = open_output(manifest, tree, options, stage_options, device, force)
        report = Report(manifest.name, device)
        ctx = RunContext(manifest, plan, tree, state, report, device, progress, stage_options, Shared())
        for decision in plan.stages:
            name = decision.name
            if not decision.run:
                report.stage(name, False, decision.reason)
            elif name in APPLIED_INSIDE:
                report.stage(name, True, f"{decision.reason} (applied in {APPLIED_INSIDE[name]})")
            elif decision.cached:
                report.metrics.update(state.metrics.get(name, {}))
                report.stage(name, False, decision.reason, state.seconds.get(name))
            else:
                before = {k: repr(v) for k, v in report.metrics.items()}
                t0 = time.perf_counter()
                details = STAGE_RUNNERS[name](ctx) or {}
                dt = time.perf_counter() - t0
                added = {k: v for k, v in report.metrics.items() if before.get(k) != repr(v)}
                state.finish(name, dt, added)
                report.stage(name, True, decision.reason, dt, **details)
        report.write(tree.root)
    return report.to_json()


def open_output(manifest: Manifest, tree: OutputTree, options: PlanOptions, stage_options: StageOptions,
                device: str, force: bool = False) -> tuple[RunState, Plan]:
    """The plan under this run's cache key, and the folder's state: resumed under the same key,
    else cleared of what earlier runs wrote (the caller holds the lock)."""
    key = inputs_key(manifest, options, stage_options, device)
    plan = make_plan(manifest, options, previous=RunState.load_raw(tree.root), key=key)
    return RunState.open(tree, key, force), plan
