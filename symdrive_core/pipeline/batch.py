"""Many scenes at once: in-process by default, or as Ray tasks on a local or remote cluster.

With Ray, each scene's frames are split into chunks rendered by separate tasks (frame outputs
are independent, atomically written files), then one task per scene finishes the plan and
writes the report: the same files and the same report as a local run.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

from ..errors import InputError
from .plan import PlanOptions, run_cameras
from .run import run_scene


def scene_out_dir(out_root: Path, package: str | Path) -> Path:
    p = Path(package)
    name = p.parent.name if p.name == "manifest.json" else p.name
    return Path(out_root) / name


def _render_chunk(package: str, out: str, camera: str, frames: list[int], device: str,
                  allow_external: bool) -> int:
    """Render some frames of one scene into its output directory (a Ray task)."""
    from ..scene import load_manifest
    from .plan import make_plan
    from .scene_render import render_frames

    manifest = load_manifest(package, allow_external=allow_external)
    plan = make_plan(manifest)
    return render_frames(manifest, plan, Path(out), [(camera, f) for f in frames], device, progress=False)


def check_all(packages: list[str], options: PlanOptions | None, allow_external: bool) -> None:
    """Every package loads, names files that are there, and plans; checked before any runs, so a
    bad package late in the list stops the batch before it has written anything."""
    from ..scene import check_files, load_manifest
    from .plan import make_plan

    for package in packages:
        manifest = load_manifest(package, allow_external=allow_external)
        check_files(manifest)
        make_plan(manifest, options)


def run_batch(packages: list[str], out_root: str | Path, *, executor: str = "local", ray_address: str | None = None,
              frames_per_task: int = 4, options: PlanOptions | None = None, device: str = "cpu",
              progress: bool = True, force: bool = False, allow_external: bool = False) -> list[dict]:
    out_root = Path(out_root)
    outs = [scene_out_dir(out_root, p) for p in packages]
    for i, out in enumerate(outs):
        if out in outs[:i]:
            first = packages[outs.index(out)]
            raise InputError(packages[i], f"its output {out} is that of {first} too: give the packages' folders "
                             "distinct names", "PACKAGES")
    check_all(packages, options, allow_external)
    run = dict(options=options, device=device, force=force, allow_external=allow_external)
    if executor == "local":
        return [run_scene(p, o, progress=progress, **run) for p, o in zip(packages, outs)]
    if executor != "ray":
        raise ValueError(f"executor: expected 'local' or 'ray', got {executor!r}")
    import ray

    from ..scene import check_files, load_manifest
    from .lock import OutputLock
    from .outputs import OutputTree
    from .run import open_output
    from .stages import StageOptions

    if not ray.is_initialized():
        ray.init(address=ray_address, include_dashboard=False, log_to_driver=False)
    render_task = ray.remote(_render_chunk)
    finish_task = ray.remote(run_scene)
    with contextlib.ExitStack() as held:  # this driver holds every scene's folder until its report
        chunks = []
        for package, out in zip(packages, outs):
            held.enter_context(OutputLock(out))
            manifest = load_manifest(package, allow_external=allow_external)
            check_files(manifest)
            open_output(manifest, OutputTree(out), options or PlanOptions(), StageOptions(), device, force)
            for name in run_cameras(manifest, (options or PlanOptions()).cameras):
                frames = list(range(len(manifest.camera(name).frames)))
                for i in range(0, len(frames), frames_per_task):
                    chunks.append(render_task.remote(str(package), str(out), name, frames[i:i + frames_per_task],
                                                     device, allow_external))
        ray.get(chunks)
        return ray.get([finish_task.remote(str(p), str(o), progress=False, lock=False, **run)
                        for p, o in zip(packages, outs)])
