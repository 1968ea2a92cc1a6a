"""Many scenes at once: in-process by default, or as Ray tasks on a local or remote cluster.

With Ray, each scene's frames are split into chunks rendered by separate tasks (frame outputs
are independent, atomically written files), then one task per scene finishes the plan and
writes the report: the same files and the same report as a local run.
"""

from __future__ import annotations

from pathlib import Path

from .plan import PlanOptions
from .run import run_scene


def scene_out_dir(out_root: Path, package: str | Path) -> Path:
    p = Path(package)
    name = p.parent.name if p.name == "manifest.json" else p.name
    return Path(out_root) / name


def _render_chunk(package: str, out: str, camera: str, frames: list[int], device: str) -> int:
    """Render some frames of one scene into its output directory (a Ray task)."""
    from ..scene import load_manifest
    from .plan import make_plan
    from .run import render_frames

    manifest = load_manifest(package)
    plan = make_plan(manifest)
    return render_frames(manifest, plan, Path(out), [(camera, f) for f in frames], device, progress=False)


def run_batch(packages: list[str], out_root: str | Path, *, executor: str = "local", ray_address: str | None = None,
              frames_per_task: int = 4, options: PlanOptions | None = None, device: str = "cpu",
              progress: bool = True) -> list[dict]:
    out_root = Path(out_root)
    outs = [scene_out_dir(out_root, p) for p in packages]
    if len(set(outs)) != len(outs):
        raise ValueError("two packages share a directory name; give them distinct names")
    if executor == "local":
        return [run_scene(p, o, options=options, device=device, progress=progress) for p, o in zip(packages, outs)]
    if executor != "ray":
        raise ValueError(f"executor: expected 'local' or 'ray', got {executor!r}")
    import ray

    from ..scene import load_manifest
    from .plan import make_plan
    from .state import RunState

    if not ray.is_initialized():
        ray.init(address=ray_address, include_dashboard=False, log_to_driver=False)
    render_task = ray.remote(_render_chunk)
    finish_task = ray.remote(run_scene)
    chunks = []
    for package, out in zip(packages, outs):
        manifest = load_manifest(package)
        plan = make_plan(manifest, options)
        RunState.open(out, plan.inputs_hash, ["render", "masks"])  # start clean if inputs changed
        for cam in manifest.cameras:
            frames = list(range(len(cam.frames)))
            for i in range(0, len(frames), frames_per_task):
                chunks.append(render_task.remote(str(package), str(out), cam.name, frames[i:i + frames_per_task], device))
    ray.get(chunks)
    return ray.get([finish_task.remote(str(p), str(o), options=options, device=device, progress=False)
                    for p, o in zip(packages, outs)])
