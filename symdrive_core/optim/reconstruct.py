"""3DGS reconstruction of a scene package's background from its training drive, on the CPU.

Kerbl et al.'s recipe at small scale: Gaussians initialised from the package's coloured point
cloud (plus a far "sky dome" seeded from the sky pixels, since nothing else can explain them; where
the depth is a sensor's, a dome of broad Gaussians fixed in place, fitted as a part of its own),
trained with L1 + 0.2 (1 - SSIM) (+ an optional inverse-depth L1 against the package's depth
maps at their measured pixels only, so sparse LiDAR depth supervises where it has returns), Adam
with per-parameter learning rates and an exponentially decaying position rate, SH degree raised
step by step, clone/split/prune density control, and optionally images coarse to fine
(``ReconstructConfig.resolution_schedule``, :mod:`.views`). Every camera that recorded an image at
every frame trains beside the first (a rig's cameras see the street from places one camera never
is); every k-th frame of the drive is held out for evaluation, from every camera. Checkpoints are
a splat PLY plus the optimizer state in safetensors, so ``--resume`` continues exactly where a run
stopped.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import torch

from ..conventions import pixel_rays_camera
from ..errors import InputError
from ..gaussians import Gaussians
from ..io.atomic import atomic_path, write_text_atomic
from ..io.ply import read_splats, write_splats
from ..io.points import read_points
from ..scene import Manifest
from ..scene.depth import measured
from ..scene.ground_truth import fitting_split
from ..scene.poses import travels
from ..shadows.layer import ShadowLayer
from ..splat.render import Layer, activate, params_from_gaussians, render_layers, render_params
from . import decompose, importance, pose_refine
from .camera_refine import (
    CameraRefinement,
    corrected_layers,
    read_cameras,
    recorded_views,
    refined_poses,
    with_refined_cameras,
    write_cameras,
)
from .config import DensifyConfig, ReconstructConfig, SkyConfig
from .densify import GradStats, densify_and_prune, ndc_gradient_norm, prune
from .exposure import Exposure
from .losses import photometric
from .recorded_shadows import RecordedShadows
from .sky import sky_mask
from .views import Levels, View, cameras_left_out, load_views, training_cameras

SHADOW_SUFFIX = ".shadow.safetensors"  # a recorded vehicle's shadow layer, beside its actors/<id>.ply
SKY_DISTANCE_FACTOR = 8.0  # sky dome radius, in scene extents (at least 150 m)
FIXED_GEOMETRY = ("means", "quats", "log_scales")  # what a fixed part does not learn
# A part that only prunes what turns transparent: no clone, no split, any size
FIXED_DENSIFY = DensifyConfig(grad_threshold=float("inf"), max_angular_size=float("inf"))


# ------------------------------------------------------------------ parameters


def gaussians_from_params(params: dict[str, torch.Tensor]) -> Gaussians:
    sh = params["sh0"]
    if "shN" in params:
        sh = torch.cat([sh, params["shN"]], 1)
    t = {n: v.detach().cpu().numpy() for n, v in params.items()}
    return Gaussians(means=t["means"], quats=t["quats"], log_scales=t["log_scales"],
                     opacity_logits=t["opacity_logits"], sh=sh.detach().cpu().numpy())


# ------------------------------------------------------------------ initialisation


def scene_extent(views: list[View]) -> tuple[float, torch.Tensor]:
    """(radius, centre) of the training cameras, 1.1x the farthest camera from their mean (3DGS)."""
    centres = torch.stack([torch.linalg.inv(v.viewmat)[:3, 3] for v in views])
    centre = centres.mean(0)
    return max(1.1 * float((centres - centre).norm(dim=1).max()), 1.0), centre


def sky_points(views: list[View], n: int, radius: float, rng: np.random.Generator, cloud: np.ndarray | None = None,
               est: SkyConfig | None = None):
    """Points on a sphere of ``radius`` around each camera, along the pixels of its sky
    (:func:`.sky.sky_mask`: its depth's where that is dense, none where it is sparse, else above
    the horizon and the skyline of ``cloud``)."""
    pts, cols = [], []
    for v in views:
        K = v.K.numpy().astype(np.float64)
        viewmat = v.viewmat.numpy().astype(np.float64)
        depth = None if v.depth is None else v.depth.numpy()
        ys, xs = np.nonzero(sky_mask(depth, K, viewmat, v.width, v.height, cloud, est or SkyConfig()))
        if len(ys) == 0:
            continue
        rays = pixel_rays_camera(K, xs, ys)
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        c2w = np.linalg.inv(viewmat)
        pts.append(radius * rays @ c2w[:3, :3].T + c2w[:3, 3])
        cols.append(v.image.numpy()[ys, xs])
    if not pts:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32)
    pts, cols = np.concatenate(pts), np.concatenate(cols)
    idx = rng.choice(len(pts), min(n, len(pts)), replace=False)
    return pts[idx].astype(np.float32), cols[idx].astype(np.float32)


def sensor_dome(manifest: Manifest, views: list[View], cfg: ReconstructConfig) -> Gaussians | None:
    """The broad dome of views whose depth is a sensor's (``SkyConfig.sensor_dome_deg``): Gaussians
    on the dome along their pixels above the horizon and the skyline of the package's points (the
    scanner's returns), each one standard deviation ``sensor_dome_deg`` across; None where no such
    view or no such pixel."""
    sensor = [replace(v, depth=None) for v in views if v.depth is not None and bool(torch.isnan(v.depth).any())]
    if not sensor or cfg.sky.sensor_dome_deg <= 0 or manifest.background_points is None:
        return None
    cloud, _ = read_points(manifest.resolve(manifest.background_points))
    radius = dome_radius(views)
    pts, cols = sky_points(sensor, cfg.sky_points, radius, np.random.default_rng(cfg.seed), cloud, cfg.sky)
    if not len(pts):
        return None
    n = len(pts)
    size = radius * np.tan(np.radians(cfg.sky.sensor_dome_deg))
    return Gaussians.from_activated(pts, np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), np.full((n, 3), size),
                                    np.full(n, cfg.init_opacity), cols)


def dome_radius(views: list[View]) -> float:
    """The sky dome's radius: ``SKY_DISTANCE_FACTOR`` scene extents, at least 150 m."""
    return max(SKY_DISTANCE_FACTOR * scene_extent(views)[0], 150.0)


def knn_scale(points: np.ndarray, k: int = 3, chunk: int = 1024) -> np.ndarray:
    """Root mean squared distance to the k nearest neighbours (the 3DGS initial scale).

    Centred and in float64: the distances come from |a|^2 + |b|^2 - 2ab, which in float32 cancels
    to zero for neighbours centimetres apart a kilometre from the origin (UTM, a long drive)."""
    points = np.asarray(points, dtype=np.float64)
    p = torch.from_numpy(np.ascontiguousarray(points - points.mean(0) if len(points) else points))
    out = torch.empty(len(p), dtype=torch.float64)
    for s in range(0, len(p), chunk):
        d2 = torch.cdist(p[s:s + chunk], p).pow_(2)
        vals = torch.topk(d2, min(k + 1, len(p)), largest=False).values[:, 1:]
        out[s:s + chunk] = vals.mean(1).sqrt()
    return out.clamp_min(1e-4).numpy().astype(np.float32)


def initial_gaussians(manifest: Manifest, views: list[View], cfg: ReconstructConfig,
                      seed: Gaussians | None = None) -> Gaussians:
    """The start of a fit: the package's point cloud, else the centres and base colours of
    ``seed`` (a reconstruction of the same scene: what a cycle reconstruction refits), plus the
    sky dome."""
    if manifest.background_points is not None:
        pts, cols = read_points(manifest.resolve(manifest.background_points))
    elif seed is not None and len(seed):
        pts, cols = seed.means, np.clip(seed.base_colors, 0.0, 1.0)
    else:
        raise InputError(manifest.path or manifest.root, "no point cloud to initialise from", "background.points")
    rng = np.random.default_rng(cfg.seed)
    if len(pts) > cfg.max_init_points:
        keep = np.sort(rng.choice(len(pts), cfg.max_init_points, replace=False))
        pts, cols = pts[keep], cols[keep]
    sp, sc = sky_points(views, cfg.sky_points, dome_radius(views), rng, pts if cfg.sky.skyline else None, cfg.sky)
    pts, cols = np.concatenate([pts, sp]), np.concatenate([cols, sc])
    n = len(pts)
    return Gaussians.from_activated(pts, np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), np.repeat(knn_scale(pts)[:, None], 3, 1),
                                    np.full(n, cfg.init_opacity), cols)


# ------------------------------------------------------------------ optimisation


def make_optimizer(params, cfg: ReconstructConfig, extent: float) -> torch.optim.Adam:
    lrs = {"means": cfg.lr_means * extent, "quats": cfg.lr_quats, "log_scales": cfg.lr_scales,
           "opacity_logits": cfg.lr_opacity, "sh0": cfg.lr_sh0, "shN": cfg.lr_shN}
    return torch.optim.Adam([{"params": [p], "lr": lrs[n], "name": n} for n, p in params.items()], eps=1e-15)


def position_lr(cfg: ReconstructConfig, extent: float, it: int) -> float:
    u = min(max(it / max(cfg.iters, 1), 0.0), 1.0)
    return extent * cfg.lr_means * (cfg.lr_means_final / cfg.lr_means) ** u


def depth_loss(info: dict, alpha: torch.Tensor, target: torch.Tensor | None) -> torch.Tensor | None:
    """L1 between rendered and true inverse depth, where the truth measured a surface (neither sky
    nor unmeasured) and the render is mostly opaque (the rasterizer's depth is alpha-normalised)."""
    pred = info.get("depth")
    if pred is None or target is None:
        return None
    pred = pred.reshape(target.shape)
    valid = measured(target) & (alpha.reshape(target.shape).detach() > 0.5)
    if not valid.any():
        return None
    return (1.0 / pred[valid].clamp_min(1e-3) - 1.0 / target[valid]).abs().mean()


# What a resumed fit must share with the one it resumes: options that shape the fit from its start.
RESUME_FIELDS = ("sh_degree", "decompose", "seed", "actor_max_gaussians", "driving_view_repeat", "exposure",
                 "densify.max_gaussians", "importance_prune")


def _same_fit(saved: dict, now: dict, path: Path) -> None:
    """A field the checkpoint's code did not have yet is not held against it."""
    missing = object()

    def get(d: dict, key: str):
        for part in key.split("."):
            d = d.get(part, missing) if isinstance(d, dict) else missing
        return d

    for key in RESUME_FIELDS:
        if get(saved, key) is not missing and get(saved, key) != get(now, key):
            raise InputError(path, f"the checkpoint was fitted with {key} = {get(saved, key)!r}, this run asks "
                             f"{get(now, key)!r}: resume with the options it started with, or start again without "
                             "--resume", "--resume")


@dataclass
class Checkpoint:
    """``gaussians.ply`` + ``state.safetensors`` (Adam moments, step counts, gradient stats)."""

    folder: Path

    def save(self, params, opt, stats: GradStats, it: int, cfg: ReconstructConfig) -> None:
        from safetensors.torch import save_file

        self.folder.mkdir(parents=True, exist_ok=True)
        write_splats(self.folder / "gaussians.ply", gaussians_from_params(params))
        tensors = {"stats.sum": stats.sum, "stats.count": stats.count}
        for group in opt.param_groups:
            st = opt.state.get(group["params"][0], {})
            for key in ("exp_avg", "exp_avg_sq", "step"):
                if key in st:
                    tensors[f"adam.{group['name']}.{key}"] = st[key].reshape(-1) if key == "step" else st[key]
        meta = {"iteration": str(it), "config": json.dumps(asdict(cfg))}
        with atomic_path(self.folder / "state.safetensors") as tmp:
            save_file({k: v.contiguous() for k, v in tensors.items()}, str(tmp), metadata=meta)

    def exists(self) -> bool:
        return (self.folder / "gaussians.ply").exists() and (self.folder / "state.safetensors").exists()

    def load(self, cfg: ReconstructConfig, extent: float):
        """The fit saved here, refused (naming the file) when it was made with other options than
        ``cfg``'s or its two files are of different iterations (a run killed between them)."""
        from safetensors import safe_open

        state = self.folder / "state.safetensors"
        g = read_splats(self.folder / "gaussians.ply")
        params = params_from_gaussians(g, cfg.sh_degree)
        opt = make_optimizer(params, cfg, extent)
        with safe_open(str(state), "pt") as f:
            it = int(f.metadata()["iteration"])
            _same_fit(json.loads(f.metadata()["config"]), asdict(cfg), state)
            if it > cfg.iters:
                raise InputError(state, f"the checkpoint is at iteration {it}, past this run's {cfg.iters}: resume "
                                 "with --iters of at least that, or start again without --resume", "--iters")
            stats = GradStats(len(g))
            stats.sum, stats.count = f.get_tensor("stats.sum"), f.get_tensor("stats.count")
            if len(stats.sum) != len(g):
                raise InputError(state, f"holds the state of {len(stats.sum)} Gaussians, gaussians.ply {len(g)}: a run "
                                 "killed between the two writes; reconstruct again without --resume", "checkpoint")
            keys = set(f.keys())
            for group in opt.param_groups:
                name = group["name"]
                if f"adam.{name}.step" in keys:
                    opt.state[group["params"][0]] = {
                        "step": f.get_tensor(f"adam.{name}.step").reshape(()),
                        "exp_avg": f.get_tensor(f"adam.{name}.exp_avg"),
                        "exp_avg_sq": f.get_tensor(f"adam.{name}.exp_avg_sq")}
        return params, opt, stats, it


@dataclass
class Part:
    """One set of Gaussians fitted with the others: the background in the world frame (``poses``
    None), or a recorded vehicle in its own frame, placed at each frame by its recorded pose."""

    name: str
    params: dict[str, torch.nn.Parameter]
    opt: torch.optim.Adam
    stats: GradStats
    extent: float
    centre: torch.Tensor
    densify: DensifyConfig
    checkpoint: Checkpoint | None = None
    poses: list | None = None  # per frame local -> world Pose, None where absent
    instance_id: int = 0
    half: np.ndarray | None = None  # a vehicle's box half extents (x length, y width, z height)
    refine: pose_refine.PoseRefinement | None = None  # a tracked vehicle's learnt pose corrections
    fixed: bool = False  # places, sizes and orientations stay as started (the sensor dome): colours and opacities learn

    @staticmethod
    def start(name: str, initial: Gaussians | None, cfg: ReconstructConfig, extent: float, centre: torch.Tensor,
              densify: DensifyConfig, checkpoint: Checkpoint | None, resume: bool, **placement) -> tuple[Part, int]:
        """A part from ``initial``, or from its checkpoint when resuming; with the iteration it starts at."""
        if resume and checkpoint is not None and checkpoint.exists():
            params, opt, stats, it = checkpoint.load(cfg, extent)
        elif initial is None:
            raise ValueError(f"fit: no initial Gaussians and no checkpoint to resume {name} from")
        else:
            params = params_from_gaussians(initial, cfg.sh_degree)
            opt, stats, it = make_optimizer(params, cfg, extent), GradStats(len(params["means"])), 0
        part = Part(name, params, opt, stats, extent, centre, densify, checkpoint, **placement)
        if part.fixed:
            for group in opt.param_groups:
                if group["name"] in FIXED_GEOMETRY:
                    group["lr"] = 0.0
        return part, it

    def present(self, frame: int) -> bool:
        return self.poses is None or self.poses[frame] is not None

    def layer(self, frame: int, degree: int) -> Layer:
        g = activate(self.params, degree)
        if self.poses is None:
            return Layer(g)
        if self.refine is not None:
            return Layer(g, *self.refine.pose(frame), self.instance_id)
        p = self.poses[frame]
        return Layer(g, torch.as_tensor(p.R, dtype=torch.float32), torch.as_tensor(p.translation, dtype=torch.float64),
                     self.instance_id)

    def gaussians(self) -> Gaussians:
        return gaussians_from_params(self.params)


def render_parts(parts: list[Part], view: View, degree: int, render_depth: bool,
                 cameras: CameraRefinement | None = None):
    """(rgb, alpha, info, present parts) of ``view``: the background alone through
    :func:`render_params` (a drive without recorded vehicles trains as it always has), else every
    part present at the frame composed in one rasterizer call, seen from the frame's corrected
    camera where ``cameras`` refines them."""
    if len(parts) == 1 and parts[0].poses is None and cameras is None:
        return (*render_params(parts[0].params, view.K, view.viewmat, view.width, view.height, degree,
                               render_depth=render_depth), parts)
    present = [p for p in parts if p.present(view.frame)]
    layers = [p.layer(view.frame, degree) for p in present]
    if cameras is not None:
        layers = corrected_layers(layers, cameras.world_inverse(view.frame))
    out = render_layers(layers, view.viewmat.double(), view.K, view.width, view.height, cull=False)
    return out["rgb"], out["alpha"], out["info"], present


def view_pool(views: list[View], parts: list[Part], cfg: ReconstructConfig) -> np.ndarray:
    """One pass over the views, as indices into ``views``: each once, and those showing a driving
    vehicle ``cfg.driving_view_repeat`` times in all (each pass is shuffled)."""
    movers = [p for p in parts if p.poses is not None and travels(p.poses, cfg.driving_m)]
    repeated = [i for i, v in enumerate(views) if any(m.present(v.frame) for m in movers)]
    return np.array(list(range(len(views))) + repeated * (cfg.driving_view_repeat - 1), dtype=np.int64)


def fit_parts(views: list[View] | Levels, parts: list[Part], cfg: ReconstructConfig, start: int, *,
              until: int | None = None, progress: bool = True, desc: str = "reconstruct", keep=None,
              shadows: RecordedShadows | None = None, exposure: Exposure | None = None,
              cameras: CameraRefinement | None = None) -> dict:
    """Optimise ``parts`` jointly against ``views`` from iteration ``start`` to ``until`` (default
    ``cfg.iters``; a fit run in segments passes its :class:`Levels` so a coarse level is computed
    once): the training loop with density control per part (``keep(part) -> [N] bool``, optional:
    which Gaussians a part may keep after each density step; ``shadows``, optional: the recorded
    vehicles' shadows laid on each render; ``exposure``, optional: each view's colour transform;
    ``cameras``, optional: the recorded camera poses' corrections).
    Every schedule is a function of the iteration, so a resumed fit continues it where it stopped. Returns a log (start iteration,
    seconds, the iteration each image downscale began at, densification steps)."""
    from tqdm import tqdm

    torch.manual_seed(cfg.seed)
    generator = torch.Generator().manual_seed(cfg.seed)
    levels = views if isinstance(views, Levels) else Levels(views)
    cfg = replace(cfg, resolution_schedule=cfg.schedule_for(max(v.width * v.height for v in levels.views)))
    n_views = len(levels.views)
    pool = view_pool(levels.views, parts, cfg)
    until = cfg.iters if until is None else min(until, cfg.iters)
    densify_until = cfg.densify_end
    depth_weight = cfg.depth_weight or 0.0  # None, not resolved for a camera (renders, as cycles fit): off
    refining = [p.refine for p in parts if p.refine is not None]
    extras = [x for x in (shadows, exposure, cameras) if x is not None]  # fitted beside the Gaussians
    log = {"resumed_from": start, "downscale": [], "densify": []}
    t0 = time.perf_counter()
    bar = tqdm(range(start, until), desc=desc, unit="it", disable=not progress, initial=start, total=cfg.iters)
    for it in bar:
        epoch, pos = divmod(it, len(pool))
        order = pool[np.random.default_rng((cfg.seed, epoch)).permutation(len(pool))]
        factor = cfg.downscale_at(it)
        if not log["downscale"] or log["downscale"][-1]["factor"] != factor:
            log["downscale"].append({"iteration": it, "factor": factor})
        view = levels.at(factor)[order[pos]]
        for part in parts:
            for group in part.opt.param_groups:
                if group["name"] == "means" and not part.fixed:
                    group["lr"] = position_lr(cfg, part.extent, it)
        degree = cfg.sh_degree_at(it)
        rgb, alpha, info, present = render_parts(parts, view, degree, depth_weight > 0, cameras)
        if shadows is not None:
            rgb = shadows.apply(rgb, info, view, present)
        if exposure is not None:
            rgb = exposure.apply(rgb, view)
        loss = photometric(rgb, view.image, cfg.ssim_lambda)
        if depth_weight > 0:
            dl = depth_loss(info, alpha, view.depth)
            if dl is not None:
                loss = loss + depth_weight * dl
        if cfg.vehicle_alpha_weight > 0 and (coverage := info.get("instance")) is not None and coverage.shape[-1]:
            loss = loss + cfg.vehicle_alpha_weight * coverage.sum(-1).mean()
        for r in refining:
            loss = loss + r.penalty(n_views)
        prior = None if exposure is None else exposure.penalty(n_views)
        if prior is not None:
            loss = loss + prior
        if cameras is not None:
            loss = loss + cameras.penalty(n_views)
        for part in parts:
            part.opt.zero_grad(set_to_none=True)
        for extra in extras:
            extra.zero_grad()
        means2d = info["means2d"]
        means2d.retain_grad()
        loss.backward()
        if it < densify_until and means2d.grad is not None:
            ndc = ndc_gradient_norm(means2d.grad, view.width, view.height)
            row = 0
            for part in present:
                n = len(part.params["means"])
                part.stats.add(ndc[row:row + n], info["visible"][row:row + n])
                row += n
        for part in parts:
            part.opt.step()
        for extra in extras:
            extra.step_at(it)
        for r in refining:
            r.step(it)
        step = it + 1
        if cfg.densify_from <= step < densify_until and step % cfg.densify_every == 0:
            for part in parts:
                counts = densify_and_prune(part.opt, part.params, part.stats, part.densify, part.extent, part.centre,
                                           generator)
                counts["pruned"] += _keep(part, keep)
                log["densify"].append({"iteration": step, "part": part.name, **counts})
        if step == densify_until and cfg.importance_prune > 0:
            log["importance_prune"] = _prune_least_important(parts, levels.at(factor), degree, cameras,
                                                             cfg.importance_prune)
        if step % 20 == 0:
            bar.set_postfix(loss=f"{loss.item():.4f}", n=sum(len(p.params["means"]) for p in parts))
        if step % cfg.checkpoint_every == 0 or step == cfg.iters:
            for part in parts:
                if part.checkpoint is not None:
                    part.checkpoint.save(part.params, part.opt, part.stats, step, cfg)
                    if part.refine is not None:
                        part.refine.save(part.checkpoint.folder)
            if parts[0].checkpoint is not None:
                for extra in extras:
                    extra.checkpoint(parts[0].checkpoint.folder)
    bar.close()
    if keep is not None and until == cfg.iters:  # Gaussians drift after the last density step: the roles hold
        # for the result too
        log["pruned_at_end"] = {part.name: _keep(part, keep) for part in parts}
    log["seconds"] = time.perf_counter() - t0
    return log


def _prune_least_important(parts: list[Part], views: list[View], degree: int, cameras, fraction: float) -> dict:
    """Remove ``fraction`` of each part's Gaussians that paint the least of ``views`` (the sensor
    dome, fixed in place, keeps its own); how many each part lost."""
    pruned = {}
    for part, weights in zip(parts, importance.blending_weights(parts, views, degree, cameras), strict=True):
        if part.fixed:
            continue
        drop = importance.least_important(weights, fraction)
        prune(part.opt, part.params, ~drop)
        part.stats.reset(len(part.params["means"]))
        pruned[part.name] = int(drop.sum())
    return pruned


def _keep(part: Part, keep) -> int:
    """Prune what ``keep(part)`` refuses; how many went."""
    if keep is None:
        return 0
    kept = keep(part)
    prune(part.opt, part.params, torch.from_numpy(kept))
    part.stats.reset(len(part.params["means"]))
    return int((~kept).sum())


def fit(views: list[View], initial: Gaussians | None, cfg: ReconstructConfig, *, checkpoint: Checkpoint | None = None,
        resume: bool = False, progress: bool = True, desc: str = "reconstruct") -> tuple[Gaussians, dict]:
    """Optimise background Gaussians ``initial`` against ``views`` (``initial`` is None only when
    resuming from ``checkpoint``). Returns the Gaussians and a log (start iteration, seconds, scene
    extent, densification steps)."""
    extent, centre = scene_extent(views)
    part, start = Part.start("background", initial, cfg, extent, centre, cfg.densify, checkpoint, resume)
    log = fit_parts(views, [part], cfg, start, progress=progress, desc=desc)
    return part.gaussians(), {**log, "extent_m": round(extent, 3)}


@dataclass
class ReconstructResult:
    gaussians: Gaussians
    metrics: dict
    output: Path
    actors: dict[str, Gaussians] = field(default_factory=dict)  # recorded vehicles, each in its own frame
    poses: dict[str, list] = field(default_factory=dict)  # tracked vehicles' refined poses, per frame
    shadows: dict[str, ShadowLayer] = field(default_factory=dict)  # recorded vehicles' shadow layers
    exposure: dict[str, np.ndarray] = field(default_factory=dict)  # cameras' colour transforms [3, 4]
    cameras: dict[str, list[np.ndarray]] = field(default_factory=dict)  # refined camera-to-world per frame


def vehicle_start(track: decompose.Track, views: list[View], n: int, rng: np.random.Generator) -> Gaussians:
    """``n`` start Gaussians of a recorded vehicle in its own frame: the surface its training views'
    depth measured in its box (at most ``n`` of those points, sized as the background's start is),
    the rest on the box's faces in the colours the views show there."""
    present = [v for v in views if track.pose_at(v.frame) is not None]

    def arrays(v: View) -> tuple:  # one float image at a time
        return v.frame, v.K.double().numpy(), v.viewmat.double().numpy(), v.image.numpy()

    pts, cols = decompose.measured_points(track, (arrays(v) + (v.depth.numpy(),) for v in present if v.depth is not None))
    if len(pts) > n:
        keep = np.sort(rng.choice(len(pts), n, replace=False))
        pts, cols = pts[keep], cols[keep]
    if len(pts) < 4:  # too few to size by their neighbours
        pts, cols = np.zeros((0, 3)), np.zeros((0, 3))
    faces, size = decompose.box_surface(track, n - len(pts), rng)
    face_cols = decompose.colour_from_views(track, faces, map(arrays, present)) if len(faces) else np.zeros((0, 3))
    means = np.concatenate([pts, faces])
    scales = np.concatenate([knn_scale(pts) if len(pts) else np.zeros(0), np.full(len(faces), size)])
    m = len(means)  # opacity 0.5: a surface the fit can thin out or fill in
    return Gaussians.from_activated(means, np.tile([1.0, 0.0, 0.0, 0.0], (m, 1)), np.repeat(scales[:, None], 3, 1),
                                    np.full(m, 0.5), np.clip(np.concatenate([cols, face_cols]), 0.0, 1.0))


def actor_parts(tracks: list[decompose.Track], views: list[View], cfg: ReconstructConfig, out: Path | None,
                resume: bool, rng: np.random.Generator,
                refine: dict[str, pose_refine.PoseRefinement] | None = None) -> list[Part]:
    """A part per recorded vehicle (:mod:`.decompose`), started by :func:`vehicle_start`
    (checkpointed under ``out`` unless it is None), with its pose corrections where ``refine`` has
    them."""
    refine = refine or {}
    parts = []
    budget = replace(cfg.densify, max_gaussians=cfg.actor_max_gaussians, max_angular_size=float("inf"))
    for t in tracks:
        initial = vehicle_start(t, views, cfg.actor_points, rng)
        checkpoint = None if out is None else Checkpoint(out / "checkpoint" / "actors" / t.actor_id)
        part, _ = Part.start(t.actor_id, initial, cfg, float(np.linalg.norm(t.half)), torch.zeros(3), budget,
                             checkpoint, resume, poses=t.poses, instance_id=t.instance_id, half=t.half,
                             refine=refine.get(t.actor_id))
        if resume and checkpoint is not None and part.refine is not None:
            part.refine.load(checkpoint.folder)
        parts.append(part)
    return parts


def keep_in_role(tracks: list[decompose.Track]):
    """The density step's extra pruning rule of a decomposed fit: a vehicle keeps what lies in its
    padded box, the background what lies outside every box of every track."""
    def keep(part: Part) -> np.ndarray:
        means = part.params["means"].detach().double().numpy()
        if part.half is not None:
            return decompose.inside_box(means, part.half)
        return ~decompose.in_swept_boxes(means, tracks)
    return keep


@dataclass
class Fit:
    """A reconstruction of a package ready to train, from its start or its checkpoint: what
    :func:`reconstruct` runs to the end at once and a benchmark runs in segments, scoring between
    them (``iteration`` advances with each :meth:`train`)."""

    cfg: ReconstructConfig  # the depth weight resolved for the cameras it trains on (the largest)
    levels: Levels
    parts: list[Part]
    keep: Callable[[Part], np.ndarray] | None
    iteration: int
    train_frames: list[int]
    heldout_frames: list[int]
    extent: float
    shadows: RecordedShadows | None = None  # the recorded vehicles' shadows, where the scene has a sun
    exposure: Exposure | None = None  # the cameras' colour transforms, where more than one trains
    sky: Part | None = None  # the sensor dome (one of ``parts``), where the depth is a sensor's
    cameras: CameraRefinement | None = None  # the recorded camera poses' corrections, where refined

    @staticmethod
    def start(manifest: Manifest, cfg: ReconstructConfig, out: Path | None = None, resume: bool = False) -> Fit:
        """The background, and with ``cfg.decompose`` one part per recorded vehicle; checkpointed
        under ``out`` (None: not at all)."""
        cameras = training_cameras(manifest)
        weights = {c.name: cfg.depth_weight_for(c) for c in cameras}
        cfg = replace(cfg, depth_weight=max(weights.values()))
        train_frames, heldout = fitting_split(manifest, cfg.holdout_every)
        views = load_views(manifest, train_frames, depth=True)
        if cfg.camera_refine.enabled:
            views = recorded_views(manifest, views)
        tracks = decompose.tracks(manifest) if cfg.decompose else []
        tracks, refine = pose_refine.refinements(manifest, tracks, cfg)
        checkpoint = None if out is None else Checkpoint(out / "checkpoint")
        initial = dome = None
        if not (resume and checkpoint is not None and checkpoint.exists()):
            initial = initial_gaussians(manifest, views, cfg)
            dome = sensor_dome(manifest, views, cfg)
            if tracks:  # points on a moving car are smeared along its path: the vehicle's part explains them
                initial = initial.subset(~decompose.in_swept_boxes(initial.means, tracks))
        extent, centre = scene_extent(views)
        background, start = Part.start("background", initial, cfg, extent, centre, cfg.densify, checkpoint, resume)
        sky = None
        sky_checkpoint = None if out is None else Checkpoint(out / "checkpoint" / "sky")
        if dome is not None or (resume and sky_checkpoint is not None and sky_checkpoint.exists()):
            sky, _ = Part.start("sky", dome, cfg, extent, centre, FIXED_DENSIFY, sky_checkpoint, resume, fixed=True)
        parts = [background, *([sky] if sky else []),
                 *actor_parts(tracks, views, cfg, out, resume, np.random.default_rng(cfg.seed), refine)]
        # the depth maps seeded the sky; the loss reads those of the cameras it weighs
        views = [v if weights[v.camera_name] else replace(v, depth=None) for v in views]
        shadows = RecordedShadows.of(manifest, tracks, cfg.shadow_lr)
        exposure = Exposure.of(views, cfg.exposure, cfg.lr_exposure)
        cams = CameraRefinement.of(views, len(manifest.frames), cfg.camera_refine, cfg.iters)
        if resume and checkpoint is not None:
            for extra in (x for x in (shadows, exposure, cams) if x is not None):
                extra.resume(checkpoint.folder)
        return Fit(cfg, Levels(views), parts, keep_in_role(tracks) if tracks else None, start, train_frames, heldout,
                   extent, shadows, exposure, sky, cams)

    def train(self, until: int | None = None, progress: bool = True) -> dict:
        """Train to iteration ``until`` (default: the end); :func:`fit_parts`' log."""
        log = fit_parts(self.levels, self.parts, self.cfg, self.iteration, until=until, progress=progress,
                        keep=self.keep, shadows=self.shadows, exposure=self.exposure, cameras=self.cameras)
        self.iteration = self.cfg.iters if until is None else min(until, self.cfg.iters)
        return log

    def gaussians(self) -> tuple[Gaussians, dict[str, Gaussians]]:
        """(background, with the sensor dome where there is one; recorded vehicles by actor id, each
        in its own frame) as they stand."""
        background = self.parts[0].params
        if self.sky is not None:
            background = {k: torch.cat([v.detach(), self.sky.params[k].detach()]) for k, v in background.items()}
        return gaussians_from_params(background), {p.name: p.gaussians() for p in self.parts[1:] if p is not self.sky}

    def layers(self) -> dict[str, ShadowLayer]:
        """The recorded vehicles' shadow layers as they stand, by actor id (none without a sun)."""
        return self.shadows.fitted() if self.shadows is not None else {}

    def poses(self) -> dict[str, list]:
        """The tracked vehicles' refined poses as they stand, by actor id (per frame, None: no box)."""
        return {p.name: p.refine.refined() for p in self.parts if p.refine is not None}

    def camera_poses(self, manifest: Manifest) -> dict[str, list[np.ndarray]]:
        """Every camera's refined camera-to-world per frame as they stand (empty: not refined)."""
        return {} if self.cameras is None else refined_poses(manifest, self.cameras)


def read_reconstruction(folder: Path) -> tuple[Gaussians, dict[str, Gaussians], dict[str, ShadowLayer]]:
    """(background, recorded vehicles by actor id, their shadow layers) as :func:`reconstruct`
    wrote them under ``folder``."""
    folder = Path(folder)
    actors = {p.stem: read_splats(p) for p in sorted((folder / "actors").glob("*.ply"))}
    layers = {name: folder / "actors" / f"{name}{SHADOW_SUFFIX}" for name in actors}
    shadows = {name: ShadowLayer.load(path) for name, path in layers.items() if path.is_file()}
    return read_splats(folder / "background.ply"), actors, shadows


def with_fitted(manifest: Manifest, poses: dict[str, list], cameras: dict[str, list[np.ndarray]]) -> Manifest:
    """``manifest`` (changed in place, and returned) with its tracked vehicles at a fit's refined
    ``poses`` (by actor id) and its cameras at the fit's refined ``cameras`` (by camera name); what
    a fit did not refine stays as recorded."""
    return with_refined_cameras(pose_refine.with_refined(manifest, poses), cameras)


def as_fitted(manifest: Manifest, folder: Path) -> Manifest:
    """:func:`with_fitted` with what the reconstruction in ``folder`` wrote."""
    return with_fitted(manifest, pose_refine.read_refined(folder), read_cameras(folder))


def reconstruct(manifest: Manifest, out: Path, cfg: ReconstructConfig | None = None, *,
                resume: bool = False, progress: bool = True) -> ReconstructResult:
    """Fit the training frames: background Gaussians, and with ``cfg.decompose`` one set per
    recorded vehicle (``existing`` actors with a box) in its own frame. Writes
    ``out/background.ply``, ``out/actors/<id>.ply``, ``out/checkpoint/``, ``out/metrics.json``
    (the fit: iterations, timings, frames), where tracked vehicles' poses were refined
    (:mod:`.pose_refine`), ``out/poses.json``, and where the scene has a sun each vehicle's shadow
    layer (:mod:`.recorded_shadows`), ``out/actors/<id>.shadow.safetensors``, and where cameras'
    colours were fitted (:mod:`.exposure`), ``out/exposure.json``, and where the camera poses were
    refined (:mod:`.camera_refine`), ``out/cameras.json``. Scoring the result is the caller's
    (``eval.views.evaluate_heldout`` on the held-out frames, :func:`with_fitted` placing the
    vehicles and cameras where they were fitted)."""
    out = Path(out)
    run = Fit.start(manifest, cfg or ReconstructConfig(), out, resume)
    start = run.iteration
    log = run.train(progress=progress)
    seconds = log["seconds"]
    g, actors = run.gaussians()
    write_splats(out / "background.ply", g)
    for name, ga in actors.items():
        write_splats(out / "actors" / f"{name}.ply", ga)
    poses = run.poses()
    if poses:
        pose_refine.write_refined(out, poses)
    exposure = {} if run.exposure is None else run.exposure.by_camera()
    if run.exposure is not None:
        run.exposure.save(out)
    shadows = run.layers()
    for name, layer in shadows.items():
        layer.save(out / "actors" / f"{name}{SHADOW_SUFFIX}")
    corrections = {p.name: {"pose_correction": p.refine.corrections()} for p in run.parts if p.refine is not None}
    cameras = run.camera_poses(manifest)
    if cameras:
        write_cameras(out, cameras, run.cameras.corrections())
    metrics = {"iterations": run.cfg.iters, "resumed_from": start, "seconds": round(seconds, 2),
               "seconds_per_iteration": round(seconds / max(run.cfg.iters - start, 1), 4),
               "gaussians": len(g), "train_frames": run.train_frames, "heldout_frames": run.heldout_frames,
               "extent_m": round(run.extent, 3), "cameras": sorted({v.camera_name for v in run.levels.views}),
               **({"cameras_left_out": left_out} if (left_out := cameras_left_out(manifest)) else {}),
               "views": len(run.levels.views), "depth_weight": run.cfg.depth_weight, "downscale": log["downscale"],
               "densify": log["densify"], **({"pruned_at_end": log["pruned_at_end"]} if "pruned_at_end" in log else {}),
               "actors": {name: {"gaussians": len(ga), **corrections.get(name, {})} for name, ga in actors.items()},
               **({"exposure": {cam: np.round(m, 4).tolist() for cam, m in exposure.items()}} if exposure else {}),
               **({"camera_correction": run.cameras.corrections()} if cameras else {})}
    write_text_atomic(out / "metrics.json", json.dumps(metrics, indent=1) + "\n")
    return ReconstructResult(g, metrics, out, actors, poses, shadows, exposure, cameras)
