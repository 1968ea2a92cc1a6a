"""The effects planner: derive the minimal stage list for one scene package, with reasons.

"Simulate only the effects a scene calls for": the plan is read off the manifest and the
asset headers alone (no torch, no model), so ``symdrive plan`` is instant and the runner
never loads a diffusion model for a scene that needs none.

* no inserted actor (or harmonization off)   -> no harmonize / finetune, no diffusion model
* no recorded vehicle removed, moved, retimed -> no inpainting of what an edit exposes
* no lateral offsets                          -> no restore / refine
* restorer weights trained on another drive   -> adapt them to this one (its recorded frames)
* actor outside every frustum in a frame      -> not rendered, not harmonized in that frame
* no sun                                      -> no cast shadows, no shadow region in the harmonization mask
* every asset SH degree 0                     -> no SH evaluation (colour is the DC term)
* stage inputs unchanged since the last run   -> its cached result is reused
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..conventions import NEAR_PLANE
from ..errors import InputError
from ..io.ply import read_header, read_splats
from ..scene import Manifest, ManifestError, box_corners_world, box_in_frustum, vehicle_local_box
from .cache_key import inputs_key

DIFFUSION_STAGES = ("inpaint", "restore", "harmonize")
# Sub-effects decided here but applied inside another stage (no runner of their own); they are
# cached exactly when their host stage is.
APPLIED_INSIDE = {"cast_shadow": "render", "sh_eval": "render"}


@dataclass
class StageDecision:
    name: str
    run: bool
    reason: str
    frames: list[int] | None = None
    actors: list[str] | None = None
    offsets: list[float] | None = None  # restore: the signed lateral offsets (metres)
    cached: bool = False


@dataclass
class PlanOptions:
    refine: bool = True
    evaluate: bool = True
    adapt: bool = True  # fine-tune the restorer on a drive its weights were not trained on
    near: float = NEAR_PLANE
    # The frame window: render, restore and harmonize only these recorded frames (None: every
    # frame). Reconstruction still fits every recorded frame; scoring keeps to the window.
    frames: list[int] | None = None
    # Signed lateral offsets to restore instead of the manifest's ``effects.lateral_offsets``
    # (``conventions.both_sides`` turns a command line's distances into these).
    offsets: tuple[float, ...] | None = None
    # The cameras rendered, restored and harmonized, by name (None: every camera). The
    # reconstruction still fits every camera that recorded images.
    cameras: tuple[str, ...] | None = None


@dataclass
class Plan:
    scene: str
    frames: int
    cameras: list[str]
    stages: list[StageDecision]
    visible: dict[str, dict[int, list[str]]]  # camera -> frame -> actor ids to render
    culled: dict[str, dict[int, list[str]]]  # camera -> frame -> actor ids dropped
    sh_degrees: dict[str, int]
    inputs_hash: str = ""
    notes: list[str] = field(default_factory=list)
    window: list[int] | None = None  # PlanOptions.frames, checked against the package


    def stage(self, name: str) -> StageDecision:
        return next(s for s in self.stages if s.name == name)

    def runs(self, name: str) -> bool:
        return self.stage(name).run

    @property
    def needs_diffusion(self) -> bool:
        return any(self.runs(n) for n in DIFFUSION_STAGES)

    def to_json(self) -> dict:
        d = asdict(self)
        d["needs_diffusion"] = self.needs_diffusion
        return d


def sh_degree_of(path: Path) -> int:
    """SH degree from a PLY header alone (count of f_rest_* properties, in ``vertex`` or, in a
    compressed file, ``sh``), without reading data."""
    header = read_header(path)
    n_rest = sum(1 for el in header.elements if el.name in ("vertex", "sh")
                 for name, _ in el.properties if name.startswith("f_rest_"))
    return round(np.sqrt(n_rest // 3 + 1)) - 1


def check_renderable(manifest: Manifest, reconstructs: bool = False) -> None:
    """Every actor can be rendered: it names a readable splat PLY (what it renders from), or no
    splats and a readable mesh (sampled into splats at render time), or it is a recorded vehicle
    with a box that this run's reconstruction fits (``reconstructs``). Otherwise the plan stops,
    naming the actor and why (``ManifestError`` at ``actors[i].assets``: exit 2)."""
    from ..io.mesh import read_mesh

    for i, a in enumerate(manifest.actors):
        if not (a.splats or a.mesh) and a.kind == "existing":
            if reconstructs:
                continue
            raise ManifestError(manifest.path or manifest.root, f"actor {a.id!r} is a recorded vehicle with no "
                                "Gaussians yet: 'symdrive reconstruct' fits it in its box (with the background)",
                                f"actors[{i}].assets")
        if a.splats:
            path, what = manifest.resolve(a.splats), f"splat file {a.splats!r}"
        elif a.mesh:
            path, what = manifest.resolve(a.mesh), f"mesh {a.mesh!r}"
        else:
            path, what = None, "a splat PLY or a mesh"
        if path is None:
            reason = "it names neither a splat PLY nor a mesh"
        elif not path.is_file():
            reason = f"{what} not found"
        else:
            try:
                if a.splats:
                    vertex = next((el for el in read_header(path).elements if el.name == "vertex"), None)
                    if vertex is None:
                        raise InputError(path, "no 'vertex' element: not a splat file")
                    if vertex.count == 0:
                        raise InputError(path, "no splats (0 vertices)")
                else:
                    read_mesh(path)
                continue
            except InputError as exc:
                reason = f"{what} cannot be read ({exc})"
        raise ManifestError(manifest.path or manifest.root, f"actor {a.id!r} cannot be rendered: {reason}",
                            f"actors[{i}].assets")


def actor_local_box(manifest: Manifest, actor) -> tuple[np.ndarray, np.ndarray]:
    """Local bounds of an actor: its ``wlh`` box, else its splats' extent (3 sigma padded), else
    its mesh's bounds."""
    if actor.wlh is not None:
        return vehicle_local_box(actor.wlh)
    if not actor.splats:
        from ..io.mesh import read_mesh

        verts = read_mesh(manifest.resolve(actor.mesh)).verts
        return verts.min(axis=0), verts.max(axis=0)
    g = read_splats(manifest.resolve(actor.splats))
    pad = 3.0 * g.scales.max(axis=1, initial=0.0)[:, None]
    return (g.means - pad).min(axis=0), (g.means + pad).max(axis=0)


def _visibility(manifest: Manifest, near: float):
    visible: dict[str, dict[int, list[str]]] = {}
    culled: dict[str, dict[int, list[str]]] = {}
    boxes = {a.id: actor_local_box(manifest, a) for a in manifest.actors}
    for cam in manifest.cameras:
        visible[cam.name], culled[cam.name] = {}, {}
        for fi, cf in enumerate(cam.frames):
            vis, cul = [], []
            for a in manifest.actors:
                pose = a.pose(fi)
                if pose is None:
                    continue
                corners = box_corners_world(*boxes[a.id], pose.R, pose.translation)
                (vis if box_in_frustum(corners, cf.world_to_camera, cf.K, cam.width, cam.height, near)
                 else cul).append(a.id)
            visible[cam.name][fi], culled[cam.name][fi] = vis, cul
    return visible, culled


def _has_ground_truth(manifest: Manifest) -> bool:
    return any(cf.image for cam in manifest.cameras for cf in cam.frames)


def _has_training_images(manifest: Manifest, cam) -> bool:
    """Whether every recorded training frame of ``cam`` has its image: refinement keeps the first
    camera's in its loss (``optim.reconstruct.load_views``), adaptation pairs the truth camera's."""
    from ..scene.ground_truth import split_frames

    train = split_frames(manifest)[0]
    return bool(train) and all(cam.frames[i].image for i in train)


def _cast_shadow(manifest: Manifest, visible, fitted: list[str]) -> StageDecision:
    """Vehicles cast shadows where the scene has a sun: inserted ones, and recorded ones whose
    decomposed fit learnt their shadow apart from the background (``fitted``: this run's fit; or
    ``assets.shadow``, :mod:`symdrive_core.optim.recorded_shadows`)."""
    sun, why = manifest.effects.casting_sun()
    casters = {a.id for a in manifest.actors if a.wlh is not None and (
        a.kind == "inserted" or a.shadow or a.id in fitted)}  # inserted: splats or mesh, all render
    frames = sorted({fi for cam in visible.values() for fi, ids in cam.items() if casters & set(ids)})
    if sun is None:
        return StageDecision("cast_shadow", False, why)
    if not frames:
        return StageDecision("cast_shadow", False, "no vehicle that casts a shadow in any frame")
    seen = sorted({a for cam in visible.values() for fi in frames for a in cam.get(fi, []) if a in casters})
    return StageDecision("cast_shadow", True, why, frames, seen)


def _window(manifest: Manifest, frames: list[int] | None) -> list[int] | None:
    """``PlanOptions.frames`` in order, each a frame of the package (else exit 2 naming it)."""
    if frames is None:
        return None
    n = len(manifest.frames)
    bad = [f for f in frames if not 0 <= int(f) < n]
    if bad or not frames:
        what = f"frame {bad[0]} is not in the package (0 to {n - 1})" if bad else "the frame window is empty"
        raise ManifestError(manifest.path or manifest.root, what, "frames")
    return sorted({int(f) for f in frames})


def run_cameras(manifest: Manifest, names: tuple[str, ...] | None) -> list[str]:
    """``PlanOptions.cameras`` in the package's order, each a camera of the package (else exit 2
    naming it); every camera when None."""
    known = [c.name for c in manifest.cameras]
    if names is None:
        return known
    bad = [n for n in names if n not in known]
    if bad or not names:
        what = (f"camera {bad[0]!r} is not in the package ({', '.join(known)})" if bad
                else "the list of cameras is empty")
        raise ManifestError(manifest.path or manifest.root, what, "cameras")
    return [n for n in known if n in names]


def _adapt(manifest: Manifest, opt: PlanOptions, restores: bool, reconstructs: bool) -> StageDecision:
    """Fine-tune the restorer on this drive's own pairs when its weights record another drive."""
    from ..diffusion.adapt import drive_identity, shipped_weights, trained_drives
    from ..scene.ground_truth import split_frames, truth_camera

    if not restores:
        return StageDecision("adapt", False, "no lateral views to restore")
    if not opt.adapt:
        return StageDecision("adapt", False, "adaptation disabled")
    cam, train = truth_camera(manifest), split_frames(manifest)[0]
    if not _has_training_images(manifest, cam):
        return StageDecision("adapt", False, f"camera {cam.name!r} lacks recorded images in its training "
                             "frames to adapt the restorer on")
    if reconstructs:
        return StageDecision("adapt", True, "the reconstruction is fitted in this run: the restorer learns "
                             "its renders of this drive", train)
    if not manifest.background_splats:
        return StageDecision("adapt", False, "no reconstruction to render training pairs from")
    drive = drive_identity(manifest, manifest.resolve(manifest.background_splats))
    seen = trained_drives(shipped_weights(guided=True))
    if any(d.get("identity") == drive["identity"] for d in seen):
        return StageDecision("adapt", False, f"the restorer was trained on this drive ({drive['identity']})")
    trained_on = (f"{seen[0].get('scene')!r} ({seen[0].get('identity')})" if len(seen) == 1
                  else f"{len(seen)} drives ({', '.join(repr(d.get('scene')) for d in seen)})" if seen
                  else "an unrecorded drive")
    return StageDecision("adapt", True, f"the restorer was trained on {trained_on}, not on this drive "
                         f"({drive['identity']})", train)


def _inpaint(manifest: Manifest, in_window: list[int], windowed: bool) -> StageDecision:
    """Inpaint what edits of recorded vehicles expose, in the frames they were edited."""
    edits = {a.id: a.edited_frames() for a in manifest.actors if a.kind == "existing"}
    edits = {aid: frames for aid, frames in edits.items() if frames}
    if not edits:
        return StageDecision("inpaint", False, "no recorded vehicle removed, moved or retimed")
    frames = sorted({f for fs in edits.values() for f in fs if f in in_window})
    if not frames:
        return StageDecision("inpaint", False, "the edits of recorded vehicles lie outside the frame window")
    return StageDecision("inpaint", True, f"{len(edits)} recorded vehicle(s) removed, moved or retimed: inpaint "
                         f"what they leave{' in the frame window' if windowed else ''}", frames, sorted(edits))


def _reconstruct(manifest: Manifest, frames: list[int]) -> StageDecision:
    if manifest.background_splats:
        return StageDecision("reconstruct", False, "background splats given")
    if not (manifest.background_points and _has_ground_truth(manifest)):
        return StageDecision("reconstruct", False, "no background splats and no images to fit")
    from ..optim.decompose import tracks
    from ..scene.ground_truth import fitting_split

    fitting_split(manifest)  # a frame to learn from, or the plan stops naming the split
    recorded = [t.actor_id for t in tracks(manifest)]
    return StageDecision("reconstruct", True, "no background splats: fit them to the images" + (
        f", and {len(recorded)} recorded vehicle(s) in their own frames" if recorded else ""), frames, recorded)


def make_plan(manifest: Manifest, options: PlanOptions | None = None, previous: dict | None = None,
              key: str | None = None) -> Plan:
    """Decide every stage for this scene. ``previous`` is the last run's state and ``key`` this
    run's cache key (see cache_key.inputs_key; by default, that of these options alone)."""
    opt = options or PlanOptions()
    eff = manifest.effects
    frames_all = list(range(len(manifest.frames)))
    stages: list[StageDecision] = [_reconstruct(manifest, frames_all)]
    check_renderable(manifest, stages[0].run)
    visible, culled = _visibility(manifest, opt.near)
    window = _window(manifest, opt.frames)
    in_window = frames_all if window is None else window
    cameras = run_cameras(manifest, opt.cameras)

    # The decisions below see only the window's frames of the cameras run; plan.visible keeps every frame.
    shown = {cam: {fi: ids for fi, ids in frames.items() if fi in in_window} for cam, frames in visible.items()
             if cam in cameras}
    stages.append(StageDecision("render", True, "always" if window is None else "the frame window", in_window,
                                sorted({a for cam in shown.values() for ids in cam.values() for a in ids})))
    stages.append(_cast_shadow(manifest, shown, (stages[0].actors or []) if stages[0].run else []))
    stages.append(_inpaint(manifest, in_window, window is not None))

    offsets = [float(o) for o in (eff.lateral_offsets if opt.offsets is None else opt.offsets)]
    stages.append(_adapt(manifest, opt, bool(offsets), stages[0].run))
    if offsets:
        offs = ", ".join(f"{o:g}" for o in offsets)
        source = "requested" if opt.offsets is None else "requested on the command line"
        stages.append(StageDecision("restore", True, f"lateral offsets {offs} m {source}", in_window,
                                    offsets=offsets))
        if not opt.refine:
            stages.append(StageDecision("refine", False, "refinement disabled"))
        elif not _has_training_images(manifest, manifest.cameras[0]):
            stages.append(StageDecision("refine", False, "no recorded images to refine against"))
        else:
            stages.append(StageDecision("refine", True, "refine the reconstruction on restored views"))
    else:
        stages.append(StageDecision("restore", False, "no lateral offsets"))
        stages.append(StageDecision("refine", False, "no restored views"))

    inserted = [a.id for a in manifest.inserted_actors]
    seen = {a for cam in shown.values() for ids in cam.values() for a in ids}
    harm_actors = [a for a in inserted if a in seen]
    harm_frames = sorted({fi for cam in shown.values() for fi, ids in cam.items()
                          if any(a in harm_actors for a in ids)})
    if not inserted:
        harm = StageDecision("harmonize", False, "no inserted actor")
    elif not eff.harmonize:
        harm = StageDecision("harmonize", False, "harmonization off in the scene's effects")
    elif not harm_frames:
        harm = StageDecision("harmonize", False, "inserted actors are outside every frustum"
                             + ("" if window is None else " in the frame window"))
    else:
        harm = StageDecision("harmonize", True, f"{len(harm_actors)} inserted actor(s) visible",
                             harm_frames, harm_actors)
    stages.append(harm)
    if harm.run and eff.finetune:
        stages.append(StageDecision("finetune", True, "fit inserted actors' colour and opacity to the "
                                    "harmonized frames", harm_frames, harm_actors))
    else:
        stages.append(StageDecision("finetune", False, "nothing harmonized" if not harm.run
                                    else "fine-tuning off in the scene's effects"))

    degrees = {}
    if manifest.background_splats:
        degrees["background"] = sh_degree_of(manifest.resolve(manifest.background_splats))
    for a in manifest.actors:
        if a.splats:
            degrees[a.id] = sh_degree_of(manifest.resolve(a.splats))
    top = max(degrees.values(), default=0)
    stages.append(StageDecision("sh_eval", top > 0, f"SH degree up to {top}" if top > 0
                                else "all assets are SH degree 0: colour is the DC term"))

    has_gt = _has_ground_truth(manifest) or bool(manifest.ground_truth)
    what = "ground truth in the package" if manifest.ground_truth else "recorded images to score held-out frames on"
    stages.append(StageDecision("evaluate", has_gt and opt.evaluate, what if has_gt and opt.evaluate
                                else ("evaluation disabled" if has_gt else "no ground truth")))

    plan = Plan(manifest.name, len(manifest.frames), cameras, stages,
                visible, culled, degrees, key or inputs_key(manifest, opt), window=window)
    if previous and previous.get("inputs_hash") == plan.inputs_hash:
        # A stage is reused only if every running stage after it is too: later stages take
        # what earlier ones hand over in memory, so the first stage to redo redoes the rest.
        done = set(previous.get("completed", []))
        for s in plan.stages:
            later = plan.stages[plan.stages.index(s):]
            host = APPLIED_INSIDE.get(s.name)
            if s.run and (plan.stage(host).cached if host else
                          all(t.name in done or t.name in APPLIED_INSIDE for t in later if t.run)):
                s.cached, s.reason = True, s.reason + " (cached: inputs unchanged)"
    return plan


def format_plan(plan: Plan) -> str:
    lines = [f"scene {plan.scene}: {plan.frames} frame(s), camera(s) {', '.join(plan.cameras)}"]
    for s in plan.stages:
        mark = "cached" if s.cached else ("run" if s.run else "skip")
        extra = ""
        if s.run and s.frames is not None:
            extra += f"  frames {_ranges(s.frames)}"
        if s.run and s.actors:
            extra += f"  actors {', '.join(s.actors)}"
        lines.append(f"  {mark:6s} {s.name:14s} {s.reason}{extra}")
    for cam, frames in plan.culled.items():
        by_actor: dict[str, list[int]] = {}
        for fi, ids in frames.items():
            for a in ids:
                by_actor.setdefault(a, []).append(fi)
        for a, fis in by_actor.items():
            lines.append(f"  culled {a} in {cam} frames {_ranges(fis)} (outside the frustum)")
    lines.append(f"  diffusion model: {'needed' if plan.needs_diffusion else 'not loaded'}")
    return "\n".join(lines)


def _ranges(frames: list[int]) -> str:
    if not frames:
        return "none"
    out, start, prev = [], frames[0], frames[0]
    for f in frames[1:] + [None]:
        if f is not None and f == prev + 1:
            prev = f
            continue
        out.append(f"{start}" if start == prev else f"{start}-{prev}")
        if f is not None:
            start = prev = f
    return ",".join(out)
