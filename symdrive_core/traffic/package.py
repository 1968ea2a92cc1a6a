"""Write the traffic scene package: the source scene with the simulated vehicles as its actors.

The new package keeps the source's frames, cameras, background and effects (file references
rewritten relative to the new package), replaces the actors with the traffic vehicles, drops
masks of the old actors, and keeps in ``ground_truth`` only what is true of the new scene: the
road, the traffic run (settings, minimum gap, manoeuvres) and where it came from. SUMO's
network and routes go to ``traffic/`` for reproduction. Written atomically, validated first.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import link_or_copy
from ..io.atomic import atomic_directory
from ..scene import Manifest, check_files, parse_manifest
from ..scene.road import Road
from .actors import traffic_actors
from .assets import Asset
from .overlap import GapReport, check_actors, require_no_overlap
from .simulate import TrafficOptions, TrafficRun

KEPT_SUMO_FILES = ("road.net.xml", "routes.rou.xml")


def _relocate(rel: str | None, src_root: Path, out: Path) -> str | None:
    return None if rel is None else os.path.relpath(src_root / rel, out)


def traffic_manifest(src: Manifest, road: Road, run: TrafficRun, assets: list[Asset], opt: TrafficOptions,
                     out: Path) -> tuple[Manifest, GapReport]:
    """The new manifest (rooted at ``out``) and its gap report; raises if any boxes overlap."""
    src_root, out = src.root.resolve(), out.resolve()
    times = np.array([f.timestamp for f in src.frames]) + run.time_offset
    actors = traffic_actors(run.tracks, {a.name: a for a in assets}, road, times, out, run.network.offset)
    gaps = check_actors(actors, len(src.frames))
    require_no_overlap(gaps)
    cameras = [replace(c, frames=[replace(cf, image=_relocate(cf.image, src_root, out),
                                          depth=_relocate(cf.depth, src_root, out))
                                  for cf in c.frames]) for c in src.cameras]
    traffic = {
        "density_per_km_lane": opt.density, "seconds": opt.seconds, "seed": opt.seed, "speed_mps": opt.speed,
        "time_offset_s": run.time_offset, "vehicles": len(actors), "vehicles_at_start": run.vehicles_at_start,
        "sumo_seconds": round(run.sumo_seconds, 4), "gaps": gaps.to_json(), "manoeuvres": run.manoeuvres,
        "network": f"traffic/{KEPT_SUMO_FILES[0]}", "routes": f"traffic/{KEPT_SUMO_FILES[1]}",
    }
    source = os.path.relpath(src.path.resolve() if src.path else src_root / "manifest.json", out)
    manifest = Manifest(
        name=f"{src.name}-traffic", frames=list(src.frames), cameras=cameras, actors=actors,
        background_splats=_relocate(src.background_splats, src_root, out),
        background_points=_relocate(src.background_points, src_root, out),
        effects=src.effects, output=src.output,
        ground_truth={"road": road.to_json(), "traffic": traffic, "source": source},
        root=out, path=out / "manifest.json")
    return manifest, gaps


def write_package(manifest: Manifest, workdir: Path) -> Path:
    """Validate and write ``manifest`` (plus SUMO's network and routes) as a whole, atomically."""
    out = manifest.root
    with atomic_directory(out) as tmp:
        _bring_in_outside_files(manifest, tmp)
        text = json.dumps(manifest.to_json(), indent=1) + "\n"
        (tmp / "manifest.json").write_text(text, encoding="utf-8")
        check_files(parse_manifest(json.loads(text), tmp / "manifest.json"))
        (tmp / "traffic").mkdir()
        for name in KEPT_SUMO_FILES:
            shutil.copy2(workdir / name, tmp / "traffic" / name)
    return out / "manifest.json"


def _bring_in_outside_files(manifest: Manifest, tmp: Path) -> None:
    """The files the new package names outside itself (the source package's images and
    background, the asset pool's cars) are linked into ``tmp`` under ``assets/`` (copied across
    file systems), so that it runs on its own and, as any package, reads nothing outside itself."""
    root = manifest.root.resolve()
    placed: dict[Path, str] = {}

    def bring(rel: str | None) -> str | None:
        if rel is None or (manifest.root / rel).resolve().is_relative_to(root):
            return rel
        src = (manifest.root / rel).resolve()
        if src not in placed:
            placed[src] = f"assets/{len(placed):04d}_{src.name}"
            link_or_copy(src, tmp / placed[src])
        return placed[src]

    manifest.background_splats = bring(manifest.background_splats)
    manifest.background_points = bring(manifest.background_points)
    for cam in manifest.cameras:
        cam.frames = [replace(cf, image=bring(cf.image), depth=bring(cf.depth)) for cf in cam.frames]
    for a in manifest.actors:
        a.splats, a.mesh = bring(a.splats), bring(a.mesh)


def check_output_path(src: Manifest, out: Path) -> None:
    """The output replaces ``out`` as a whole: it must not be, or contain, the source package."""
    src_root, out = src.root.resolve(), Path(out).resolve()
    if out == src_root or out in src_root.parents:
        raise InputError(out, "the output would replace the source package; choose another --out")
