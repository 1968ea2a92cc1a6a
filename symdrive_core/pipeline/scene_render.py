"""Render a scene package's frames: background plus every visible actor at its pose.

Loads each asset once (as activated tensors) and reuses it for every frame; actors the plan
culled for a frame are never handed to the rasterizer. An actor renders from its splat PLY when
it names one, else from its mesh, sampled into splats (:func:`actor_splats`) and, given a cache
folder, written there once so later runs and stages read the same splats back.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from .. import conventions
from ..errors import InputError
from ..gaussians import Gaussians
from ..insertion.config import MESH_SAMPLES
from ..io.images import write_image, write_mask
from ..io.ply import read_splats
from ..scene import Manifest
from ..scene.camera import CameraView
from .outputs import ASSET_CACHE, OutputTree
from .plan import Plan

MESH_SEED = 0
MESH_CONVERSION = "mesh_to_splats/1"  # part of the cache key: change it when the conversion changes


def mesh_cache_path(cache_dir: Path, actor_id: str, mesh_path: Path, n_samples: int, seed: int) -> Path:
    """Where an actor's mesh-sampled splats are cached: keyed by the mesh file's bytes and the sampling."""
    h = hashlib.sha256(f"{MESH_CONVERSION}:{n_samples}:{seed}:".encode())
    with open(mesh_path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", actor_id)
    return Path(cache_dir) / "mesh_splats" / f"{safe}.{h.hexdigest()[:16]}.ply"


def actor_splats(manifest: Manifest, actor, cache_dir: Path | None = None, *, n_samples: int = MESH_SAMPLES,
                 seed: int = MESH_SEED) -> Gaussians:
    """An actor's Gaussians in its own frame: its splat PLY, else its mesh sampled into splats
    (read back from ``cache_dir`` when an earlier call wrote them there)."""
    from ..insertion.mesh_to_splats import mesh_to_splats
    from ..io.mesh import read_mesh
    from ..io.ply import write_splats

    if actor.splats:
        return read_splats(manifest.resolve(actor.splats))
    if not actor.mesh:
        raise InputError(manifest.path or manifest.root, f"actor {actor.id!r} has neither splats nor a mesh",
                         "actors.assets")
    mesh_path = manifest.resolve(actor.mesh)
    cached = None
    if cache_dir is not None and mesh_path.is_file():
        cached = mesh_cache_path(cache_dir, actor.id, mesh_path, n_samples, seed)
        if cached.is_file():
            return read_splats(cached)
    g = mesh_to_splats(read_mesh(mesh_path), n_samples, seed=seed)
    if cached is not None:
        cached.parent.mkdir(parents=True, exist_ok=True)
        write_splats(cached, g)
    return g


@dataclass
class FrameRender:
    rgb: np.ndarray  # [H, W, 3]
    alpha: np.ndarray  # [H, W]
    depth: np.ndarray  # [H, W], expected camera z (0 where empty)
    instance: dict[str, np.ndarray]  # actor id -> accumulated alpha [H, W]
    shadow: np.ndarray | None = None  # [H, W] occlusion of the sun by inserted vehicles, when cast


class SceneRenderer:
    def __init__(self, manifest: Manifest, *, device: str = "cpu", background_color=(0.0, 0.0, 0.0),
                 antialiased: bool = False, background_gaussians=None, actor_gaussians: dict | None = None,
                 asset_cache: Path | None = None, actor_shadows: dict | None = None):
        """``asset_cache``: folder for mesh-only actors' sampled splats (for ``symdrive run``,
        ``<out>/insertion_assets``); without it they are sampled in memory. ``actor_shadows``:
        recorded vehicles' shadow layers by actor id (a reconstruction this run fitted), in place
        of the package's (``assets.shadow``)."""
        from ..shadows.layer import package_layers
        from ..splat.tensors import GaussianTensors

        self.manifest = manifest
        self.device = torch.device(device)
        self.antialiased = antialiased
        self.background_color = torch.tensor(background_color, dtype=torch.float32, device=self.device)
        bg = background_gaussians
        if bg is None and manifest.background_splats:
            bg = read_splats(manifest.resolve(manifest.background_splats))
        self.background = None if bg is None else GaussianTensors.from_gaussians(bg, device=self.device)
        self.actors = {}
        self.sources = {}  # inserted actor id -> Gaussians as read (what its cast shadow is computed from)
        self.shadow_layers = package_layers(manifest) | dict(actor_shadows or {})  # recorded vehicles' own shadows
        for a in manifest.actors:
            g = (actor_gaussians or {}).get(a.id)
            if g is None and (a.splats or a.mesh):
                g = actor_splats(manifest, a, asset_cache)
            if g is not None:
                if a.kind == "inserted" and not isinstance(g, GaussianTensors):
                    self.sources[a.id] = g
                self.actors[a.id] = g if isinstance(g, GaussianTensors) else GaussianTensors.from_gaussians(
                    g, device=self.device)

    def view(self, camera: str, frame: int, lateral_offset_m: float = 0.0) -> CameraView:
        """Camera ``camera`` at ``frame``, moved ``lateral_offset_m`` along its own +x."""
        cam = self.manifest.camera(camera)
        cf = cam.frames[frame]
        c2w = conventions.lateral_shift(cf.camera_to_world, lateral_offset_m) if lateral_offset_m else cf.camera_to_world
        return CameraView(conventions.invert_rigid(c2w), cf.K, cam.width, cam.height)

    def render(self, camera: str, frame: int, actor_ids: list[str] | None = None, *,
               lateral_offset_m: float = 0.0, with_background: bool = True, recorded: bool = False) -> FrameRender:
        """``recorded``: existing actors where the drive saw them (their recorded poses), not as edited."""
        from ..splat.render import render_scene

        def pose_of(actor):
            return actor.recorded_pose(frame) if recorded else actor.pose(frame)

        ids = [a.id for a in self.manifest.actors if pose_of(a) is not None] if actor_ids is None else actor_ids
        placed = []
        for aid in ids:
            if aid not in self.actors:
                continue
            actor = self.manifest.actor(aid)
            pose = pose_of(actor)
            if pose is not None:
                placed.append((self.actors[aid], pose, actor.instance_id))
        out = render_scene(self.background if with_background else None, placed,
                           self.view(camera, frame, lateral_offset_m), background_color=self.background_color,
                           antialiased=self.antialiased)
        by_instance = {a.instance_id: a.id for a in self.manifest.actors}
        instance = {}
        for k, iid in enumerate(out["actor_ids"]):
            instance[by_instance[iid]] = out["instance"][..., k].detach().cpu().numpy()
        return FrameRender(out["rgb"].detach().cpu().numpy(), out["alpha"][..., 0].detach().cpu().numpy(),
                           out["depth"][..., 0].detach().cpu().numpy(), instance)

    def cast_shadows(self, camera: str, frame: int, render: FrameRender, actor_ids: list[str], sun_direction,
                     ratio: float) -> FrameRender:
        """``render`` with the sun shadows of ``actor_ids`` laid on its background
        (:mod:`symdrive_core.shadows.cast`): an inserted vehicle's cast by its Gaussians, a
        recorded one's its learnt layer; vehicles stay as rendered."""
        from ..shadows.cast import lay_shadows, vehicle_shadow_map

        maps = []
        for aid in actor_ids:
            actor = self.manifest.actor(aid)
            pose = actor.pose(frame)
            if pose is None or actor.wlh is None:
                continue
            if aid in self.shadow_layers:
                maps.append(self.shadow_layers[aid].at(pose, actor.wlh))
            elif aid in self.sources:
                maps.append(vehicle_shadow_map(self.sources[aid], pose, actor.wlh, sun_direction))
        maps = [m for m in maps if m is not None]
        if not maps:
            return render
        cf = self.manifest.camera(camera).frames[frame]
        background = self.render(camera, frame, [])
        rgb, occlusion = lay_shadows(render.rgb, render.instance.values(), background.rgb, background.depth, maps,
                                     cf.camera_to_world, cf.K, ratio)
        return replace(render, rgb=rgb, shadow=occlusion)


def render_frames(manifest: Manifest, plan: Plan, out: Path | OutputTree, jobs: list[tuple[str, int]], device: str,
                  progress: bool = True, background=None, actors: dict | None = None,
                  shadows: dict | None = None) -> int:
    """Render (camera, frame) jobs whose outputs are missing into the output tree (RGB written last:
    its presence marks the frame complete); returns how many were rendered. ``background``:
    Gaussians to use instead of the manifest's (a reconstruction this run fitted), ``actors`` its
    recorded vehicles' by actor id, ``shadows`` their shadow layers."""
    out = out if isinstance(out, OutputTree) else OutputTree(out)
    renderer = None
    done = 0
    casting = plan.stage("cast_shadow")
    for cam, fi in tqdm(jobs, desc="render", unit="frame", disable=not progress):
        rgb_path = out.frame("render", cam, fi)
        if rgb_path.exists():
            continue
        if renderer is None:
            renderer = SceneRenderer(manifest, device=device, asset_cache=out.folder(ASSET_CACHE),
                                     background_gaussians=background, actor_gaussians=actors,
                                     actor_shadows=shadows)
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
