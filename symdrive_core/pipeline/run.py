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

from ..scene import Manifest, check_files, load_manifest
from .cache_key import inputs_key
from .lock import OutputLock
from .outputs import REPORT, OutputTree, unmade_if_refused
from .plan import APPLIED_INSIDE, Plan, PlanOptions, make_plan
from .report import Report
from .stages import STAGE_RUNNERS, Shared, StageOptions, merge_metrics
from .state import RunState


@dataclass
class RunContext:
    manifest: Manifest
    plan: Plan
    tree: OutputTree
    state: RunState
    device: str
    progress: bool
    options: StageOptions
    shared: Shared


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
    with unmade_if_refused(tree.root), OutputLock(tree.root) if lock else contextlib.nullcontext():
        state, plan = open_output(manifest, tree, options, stage_options, device, force)
        report = Report(manifest.name, device, extra={"cameras": plan.cameras})
        ctx = RunContext(manifest, plan, tree, state, device, progress, stage_options, Shared())
        for decision in plan.stages:
            name = decision.name
            if not decision.run:
                report.stage(name, False, decision.reason)
            elif name in APPLIED_INSIDE:
                report.stage(name, True, f"{decision.reason} (applied in {APPLIED_INSIDE[name]})")
            elif decision.cached:
                merge_metrics(report.metrics, state.metrics.get(name, {}))
                report.stage(name, False, decision.reason, state.seconds.get(name))
            else:
                t0 = time.perf_counter()
                result = STAGE_RUNNERS[name](ctx)
                dt = time.perf_counter() - t0
                state.finish(name, dt, result.metrics)
                merge_metrics(report.metrics, result.metrics)
                report.stage(name, True, decision.reason, dt, result.details)
        report.write(tree.path(REPORT))
    return report.to_json()


def open_output(manifest: Manifest, tree: OutputTree, options: PlanOptions, stage_options: StageOptions,
                device: str, force: bool = False) -> tuple[RunState, Plan]:
    """The plan under this run's cache key, and the folder's state: resumed under the same key,
    else cleared of what earlier runs wrote (the caller holds the lock)."""
    key = inputs_key(manifest, options, stage_options, device)
    plan = make_plan(manifest, options, previous=RunState.load_raw(tree.root), key=key)
    return RunState.open(tree, key, force), plan
