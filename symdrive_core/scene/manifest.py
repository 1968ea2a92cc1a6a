"""Scene package: ``manifest.json`` loaded into typed objects, validated field by field.

A scene package is a directory with ``manifest.json`` and the files it names (paths relative
to the manifest). Every error names the JSON field path, e.g.
``actors[2].poses[17].rotation: expected 4 numbers``. numpy only (the add-on writes these).
The JSON Schema in ``manifest.schema.json`` describes the same format for other tools.
"""

from __future__ import annotations

import json
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import conventions
from ..errors import InputError
from ..io import open_regular
from ..io.atomic import write_text_atomic
from ..io.images import MAX_IMAGE_SIDE
from .depth import DEPTH_ZERO
from .fields import FieldReader
from .paths import check_relative, is_inside, resolve_inside
from .poses import Pose
from .schema import SCHEMA_PATH, schema_problems  # noqa: F401 - SCHEMA_PATH: where the format is defined

FORMAT = "symdrive-scene"
VERSION = 1
ACTOR_KINDS = ("existing", "inserted")
# Bounds that keep every later computation finite (float32 included) and every allocation small.
FOCAL_RANGE = (1e-2, 1e7)  # fx, fy in pixels
PRINCIPAL_MAX = 1e7  # |cx|, |cy|, |skew| in pixels
COORD_MAX = 1e7  # |translation| in metres: 10 000 km holds UTM and Earth-centred coordinates
# Beyond this distance from the origin float32, in which splat PLYs store positions, steps by more
# than a centimetre: such a package loads, with a warning to move its origin near the drive.
FLOAT32_NEAR_M = 2.0 ** 17
WLH_MAX = 1000.0  # metres
OFFSET_MAX = 1000.0  # lateral offsets, metres
ID_MAX = 65535  # instance ids: id maps are 16-bit
JSON_DEPTH_MAX = 64
MANIFEST_BYTES_MAX = 512 * 1024 * 1024


class ManifestError(InputError):
    """An invalid manifest: ``field`` is the JSON path of the offending value."""


@dataclass
class Frame:
    index: int
    timestamp: float


@dataclass
class CameraFrame:
    K: np.ndarray  # [3, 3]
    camera_to_world: np.ndarray  # [4, 4] OpenCV
    world_to_camera: np.ndarray  # [4, 4]
    image: str | None = None  # ground-truth image, relative to the package
    depth: str | None = None
    # The pose the recording gave, when a reconstruction refined ``camera_to_world`` (None: not
    # refined): what a later refinement starts from again.
    recorded_camera_to_world: np.ndarray | None = None

    @property
    def recorded(self) -> np.ndarray:
        """The recording's camera-to-world, before any refinement."""
        return self.camera_to_world if self.recorded_camera_to_world is None else self.recorded_camera_to_world


@dataclass
class Camera:
    name: str
    width: int
    height: int
    frames: list[CameraFrame]
    depth_zero: str = "sky"  # what 0 in this camera's depth maps means (see scene/depth.py)


@dataclass
class Actor:
    id: str
    kind: str  # "existing" | "inserted"
    splats: str | None
    mesh: str | None
    poses: list[Pose | None]  # one per frame; None = not in the scene in that frame
    wlh: np.ndarray | None = None
    instance_id: int = 0  # 1-based id used in id-map masks and instance channels
    # An existing actor's poses as the drive recorded them, when an edit changed ``poses`` (None:
    # unedited, the recorded poses are ``poses``). Its Gaussians are fitted at these.
    recorded_poses: list[Pose | None] | None = None
    # The tracks' boxes, when a reconstruction refined them (its refined poses are then the
    # recorded poses): what a later refinement starts from again. None: not refined.
    tracked_poses: list[Pose | None] | None = None
    # A recorded vehicle's shadow layer (:mod:`symdrive_core.shadows.layer`), as its
    # decomposed fit learnt it: laid where the scene has a sun. None: its shadow is not its own.
    shadow: str | None = None

    def pose(self, frame: int) -> Pose | None:
        return self.poses[frame]

    def recorded_pose(self, frame: int) -> Pose | None:
        """Where the drive saw this actor at ``frame`` (an existing actor's track, before edits)."""
        return (self.recorded_poses or self.poses)[frame]

    def edited_frames(self, tolerance_m: float = 1e-3) -> list[int]:
        """Frames where the edited pose leaves the recorded one: removed, moved or retimed there."""
        if self.recorded_poses is None:
            return []
        return [f for f, (r, p) in enumerate(zip(self.recorded_poses, self.poses))
                if r is not None and (p is None or not p.close_to(r, tolerance_m))]


@dataclass
class MaskEntry:
    camera: str
    frame: int
    actor: str
    amodal: str | None = None
    visible: str | None = None


@dataclass
class IdMap:
    camera: str
    frame: int
    path: str
    ids: dict[int, str]


# A clear-sky street: skylight is a quarter to a half of the light on sunlit ground (more in a
# street canyon, whose facades light the shade). Scenes set their own as ``effects.shadow_ratio``.
DEFAULT_SHADOW_RATIO = 0.4


@dataclass
class Effects:
    lateral_offsets: list[float] = field(default_factory=list)
    harmonize: bool = False
    finetune: bool = False
    shadows: bool = False
    sun_direction: np.ndarray | None = None  # direction light travels, world frame, unit
    # Fraction of its light the ground keeps in full shadow (skylight over sun plus sky); None:
    # DEFAULT_SHADOW_RATIO.
    shadow_ratio: float | None = None

    @property
    def shade(self) -> float:
        """The fraction of its light the ground keeps in a vehicle's full shadow in this scene."""
        return DEFAULT_SHADOW_RATIO if self.shadow_ratio is None else float(self.shadow_ratio)

    def casting_sun(self) -> tuple[np.ndarray | None, str]:
        """The unit direction sunlight travels when vehicles cast ground shadows (else
        None), and why or why not: the one rule the planner's ``cast_shadow`` decision and every
        renderer of a cast shadow read."""
        if self.sun_direction is None:
            return None, "no sun in the scene"
        if not self.shadows:
            return None, "shadows off in the scene's effects"
        sun = conventions.sun_above_horizon(self.sun_direction)
        if sun is None:
            return None, "sun at or below the horizon"
        return sun, f"sun present: vehicles cast shadows (shade keeps {self.shade:.2f} of the light)"


@dataclass
class Manifest:
    name: str
    frames: list[Frame]
    cameras: list[Camera]
    actors: list[Actor]
    background_splats: str | None = None
    background_points: str | None = None
    masks: list[MaskEntry] = field(default_factory=list)
    id_maps: list[IdMap] = field(default_factory=list)
    effects: Effects = field(default_factory=Effects)
    output: str = "output"
    ground_truth: dict = field(default_factory=dict)
    # Where an imported package came from: ``transform`` maps the source frame to this world.
    source: dict = field(default_factory=dict)
    root: Path = field(default_factory=Path.cwd)
    path: Path | None = None
    # Whether asset paths may lead outside the package (``--allow-external-assets``).
    allow_external: bool = field(default=False, compare=False)

    def resolve(self, rel: str | None, where: str | None = None) -> Path | None:
        """``rel`` (a path from the manifest) as a path to read, refused with :class:`InputError`
        naming the field unless it lies inside the package once symlinks are resolved (absolute
        paths and ``..`` that climb out included), or ``allow_external`` was given at load. FIFOs,
        devices and sockets are refused in every case."""
        if rel is None:
            return None
        return resolve_inside(self.root, rel, where or (lambda: self.field_of(rel)), self.path or self.root,
                              allow_external=self.allow_external)

    def asset_refs(self) -> list[tuple[str, str]]:
        """(field path, path as written) of every file the manifest names outside ``ground_truth``."""
        refs: list[tuple[str, str | None]] = [("background.splats", self.background_splats),
                                              ("background.points", self.background_points)]
        for ci, c in enumerate(self.cameras):
            for fi, cf in enumerate(c.frames):
                refs += [(f"cameras[{ci}].frames[{fi}].image", cf.image),
                         (f"cameras[{ci}].frames[{fi}].depth", cf.depth)]
        for ai, a in enumerate(self.actors):
            refs += [(f"actors[{ai}].assets.splats", a.splats), (f"actors[{ai}].assets.mesh", a.mesh),
                     (f"actors[{ai}].assets.shadow", a.shadow)]
        for mi, e in enumerate(self.masks):
            refs += [(f"masks.entries[{mi}].amodal", e.amodal), (f"masks.entries[{mi}].visible", e.visible)]
        for mi, e in enumerate(self.id_maps):
            refs.append((f"masks.id_maps[{mi}].path", e.path))
        return [(w, r) for w, r in refs if r is not None]

    def ground_truth_refs(self) -> list[tuple[str, str, str | None]]:
        """(field path, path as written, the camera whose size it has) of every image
        ``ground_truth`` names (see :mod:`.ground_truth` for its layout)."""
        gt = self.ground_truth or {}
        refs: list[tuple[str, Any, Any]] = []

        def frames(entry: dict, where: str, camera) -> None:
            for k, rel in (entry.get("frames") or {}).items():
                refs.append((f"{where}.frames.{k}", rel, entry.get("camera", camera)))

        for li, e in enumerate(gt.get("lateral", [])):
            frames(e, f"ground_truth.lateral[{li}]", gt.get("camera"))
        lanes = gt.get("lanes") or {}
        for k, rel in (lanes.get("recorded") or {}).items():
            refs.append((f"ground_truth.lanes.recorded.{k}", rel, lanes.get("camera")))
        for li, e in enumerate(lanes.get("lateral", [])):
            frames(e, f"ground_truth.lanes.lateral[{li}]", lanes.get("camera"))
        for key, entries in (("insertion", ("with", "without", "mask", "shadow_mask")), ("edits", ("image", "mask"))):
            for i, e in enumerate(gt.get(key, [])):
                refs += [(f"ground_truth.{key}[{i}].{k}", e[k], e.get("camera")) for k in entries if e.get(k)]
        if gt.get("vehicles"):
            frames(gt["vehicles"], "ground_truth.vehicles", None)
        return [(w, r, c) for w, r, c in refs if isinstance(r, str)]

    def field_of(self, rel: str) -> str:
        """The field path that holds ``rel`` (for messages), ``ground_truth`` included."""
        for where, r in self.asset_refs():
            if r == rel:
                return where
        stack: list[tuple[str, Any]] = [("ground_truth", self.ground_truth)]
        while stack:
            where, v = stack.pop()
            if v == rel:
                return where
            if isinstance(v, dict):
                stack += [(f"{where}.{k}", x) for k, x in v.items()]
            elif isinstance(v, list):
                stack += [(f"{where}[{i}]", x) for i, x in enumerate(v)]
        return "path"

    def output_dir(self) -> Path:
        """The package's output folder (``output``, relative), refused if a symlink on the way
        leads it out of the package."""
        out = self.root / check_relative(self.output, "output", self.path or self.root)
        if not is_inside(out, self.root):
            raise ManifestError(self.path or self.root, f"{self.output!r} leads outside the package (a symlink)",
                                "output")
        return out

    def camera(self, name: str) -> Camera:
        for c in self.cameras:
            if c.name == name:
                return c
        raise KeyError(f"no camera named {name!r}")

    def actor(self, actor_id: str) -> Actor:
        for a in self.actors:
            if a.id == actor_id:
                return a
        raise KeyError(f"no actor with id {actor_id!r}")

    @property
    def inserted_actors(self) -> list[Actor]:
        return [a for a in self.actors if a.kind == "inserted"]

    def to_json(self) -> dict:
        def camera_frame(cf: CameraFrame) -> dict:
            d = {"K": cf.K.tolist(), "camera_to_world": cf.camera_to_world.tolist(),
                 "world_to_camera": cf.world_to_camera.tolist()}
            if cf.recorded_camera_to_world is not None:
                d["recorded_camera_to_world"] = cf.recorded_camera_to_world.tolist()
            if cf.image is not None:
                d["image"] = cf.image
            if cf.depth is not None:
                d["depth"] = cf.depth
            return d

        out: dict[str, Any] = {
            "format": FORMAT,
            "version": VERSION,
            "name": self.name,
            "conventions": {"world": "z-up", "units": conventions.UNITS,
                            "camera": conventions.CAMERA_CONVENTION,
                            "pixel_center": conventions.PIXEL_CENTER_OFFSET,
                            "quaternion": conventions.QUATERNION_ORDER},
            "frames": [{"index": f.index, "timestamp": f.timestamp} for f in self.frames],
            "cameras": [{"name": c.name, "width": c.width, "height": c.height,
                         **({} if c.depth_zero == "sky" else {"depth_zero": c.depth_zero}),
                         "frames": [camera_frame(cf) for cf in c.frames]} for c in self.cameras],
            "background": {"splats": self.background_splats, "points": self.background_points},
            "actors": [{
                "id": a.id, "kind": a.kind, "instance_id": a.instance_id,
                "assets": {"splats": a.splats, "mesh": a.mesh, **({} if a.shadow is None else {"shadow": a.shadow})},
                **({"wlh": [float(v) for v in a.wlh]} if a.wlh is not None else {}),
                "poses": [None if p is None else p.to_json() for p in a.poses],
                **({} if a.recorded_poses is None else {
                    "recorded_poses": [None if p is None else p.to_json() for p in a.recorded_poses]}),
                **({} if a.tracked_poses is None else {
                    "tracked_poses": [None if p is None else p.to_json() for p in a.tracked_poses]}),
            } for a in self.actors],
            "masks": {
                "entries": [{k: v for k, v in vars(m).items() if v is not None} for m in self.masks],
                "id_maps": [{"camera": m.camera, "frame": m.frame, "path": m.path,
                             "ids": {str(k): v for k, v in m.ids.items()}} for m in self.id_maps],
            },
            "effects": {
                "lateral_offsets": [float(v) for v in self.effects.lateral_offsets],
                "harmonize": self.effects.harmonize, "finetune": self.effects.finetune,
                "shadows": self.effects.shadows,
                "sun_direction": None if self.effects.sun_direction is None
                else [float(v) for v in self.effects.sun_direction],
                "shadow_ratio": None if self.effects.shadow_ratio is None else float(self.effects.shadow_ratio),
            },
            "output": self.output,
        }
        if self.ground_truth:
            out["ground_truth"] = self.ground_truth
        if self.source:
            out["source"] = self.source
        return out

    def save(self, path: str | os.PathLike | None = None) -> Path:
        path = Path(path) if path is not None else (self.path or self.root / "manifest.json")
        write_text_atomic(path, json.dumps(self.to_json(), indent=1) + "\n")
        return path


# ---------------------------------------------------------------- parsing with field paths


class _Reader(FieldReader):
    error = ManifestError


def _check_depth(rd: "_Reader", data: Any) -> None:
    """No value nested deeper than ``JSON_DEPTH_MAX`` (iteratively: deep input cannot recurse)."""
    stack: list[tuple[Any, int, str]] = [(data, 0, "(root)")]
    while stack:
        v, depth, where = stack.pop()
        if depth > JSON_DEPTH_MAX:
            rd.fail(where, f"nested deeper than {JSON_DEPTH_MAX} levels")
        if isinstance(v, dict):
            stack += [(x, depth + 1, f"{where}.{k}" if where != "(root)" else str(k)) for k, x in v.items()]
        elif isinstance(v, list):
            stack += [(x, depth + 1, f"{where}[{i}]") for i, x in enumerate(v)]


# ---------------------------------------------------------------- ground truth: what the schema cannot say

def _check_ground_truth_refs(rd: "_Reader", gt: dict, cam_names: set, nf: int) -> None:
    """Cameras that ``ground_truth`` names exist; frame indices it gives lie in the package."""
    def camera(v, where):
        if v not in cam_names:
            rd.fail(where, f"no camera named {v!r}")

    def frame(i, where):
        if int(i) >= nf:
            rd.fail(where, f"frame {i} out of range (package has {nf})")

    if "camera" in gt:
        camera(gt["camera"], "ground_truth.camera")
    for key in ("train_frames", "heldout_frames"):
        for i, f in enumerate(gt.get(key, [])):
            frame(f, f"ground_truth.{key}[{i}]")
    def lateral(entries, where):
        for li, e in enumerate(entries):
            off = e.get("offset_m")
            if isinstance(off, bool) or not isinstance(off, (int, float)) or not np.isfinite(off):
                rd.fail(f"{where}[{li}].offset_m", f"expected a finite offset in metres, got {off!r}")
            if "camera" in e:
                camera(e["camera"], f"{where}[{li}].camera")
            for k in e["frames"]:
                frame(k, f"{where}[{li}].frames.{k}")

    lateral(gt.get("lateral", []), "ground_truth.lateral")
    lanes = gt.get("lanes", {})
    if lanes and "road" not in gt:
        rd.fail("ground_truth.lanes", "lane masks are scored inside the road: ground_truth.road is missing")
    if "camera" in lanes:
        camera(lanes["camera"], "ground_truth.lanes.camera")
    for k in lanes.get("recorded", {}):
        frame(k, f"ground_truth.lanes.recorded.{k}")
    lateral(lanes.get("lateral", []), "ground_truth.lanes.lateral")
    for ii, e in enumerate(gt.get("insertion", [])):
        if "camera" in e:
            camera(e["camera"], f"ground_truth.insertion[{ii}].camera")
        if "frame" in e:
            frame(e["frame"], f"ground_truth.insertion[{ii}].frame")
    vehicles = gt.get("vehicles", {})
    if "camera" in vehicles:
        camera(vehicles["camera"], "ground_truth.vehicles.camera")
    for k in vehicles.get("frames", {}):
        frame(k, f"ground_truth.vehicles.frames.{k}")
    for ei, e in enumerate(gt.get("edits", [])):
        if "camera" in e:
            camera(e["camera"], f"ground_truth.edits[{ei}].camera")
        if "frame" in e:
            frame(e["frame"], f"ground_truth.edits[{ei}].frame")


def _frames(rd: _Reader, d: dict) -> list[Frame]:
    frames = []
    for i, f in enumerate(rd.lst(rd.key(d, "frames", ""), "frames")):
        w = f"frames[{i}]"
        f = rd.obj(f, w)
        idx = rd.integer(rd.key(f, "index", w), f"{w}.index")
        if idx != i:
            rd.fail(f"{w}.index", f"expected {i} (frames are listed in order from 0)")
        frames.append(Frame(idx, rd.num(rd.key(f, "timestamp", w), f"{w}.timestamp")))
    if not frames:
        rd.fail("frames", "expected at least one frame")
    for i in range(1, len(frames)):
        if frames[i].timestamp <= frames[i - 1].timestamp:
            rd.fail(f"frames[{i}].timestamp", "timestamps must increase")
    return frames


def _cameras(rd: _Reader, d: dict, nf: int) -> list[Camera]:
    cameras = []
    for ci, c in enumerate(rd.lst(rd.key(d, "cameras", ""), "cameras")):
        w = f"cameras[{ci}]"
        c = rd.obj(c, w)
        cname = rd.name(rd.key(c, "name", w), f"{w}.name")
        if any(x.name == cname for x in cameras):
            rd.fail(f"{w}.name", f"duplicate camera name {cname!r}")
        width = rd.integer(rd.key(c, "width", w), f"{w}.width", 1, MAX_IMAGE_SIDE)
        height = rd.integer(rd.key(c, "height", w), f"{w}.height", 1, MAX_IMAGE_SIDE)
        depth_zero = c.get("depth_zero", "sky")
        if depth_zero not in DEPTH_ZERO:
            rd.fail(f"{w}.depth_zero", f"expected one of {', '.join(DEPTH_ZERO)}, got {depth_zero!r}")
        cfs = rd.lst(rd.key(c, "frames", w), f"{w}.frames")
        if len(cfs) != nf:
            rd.fail(f"{w}.frames", f"expected {nf} entries (one per frame), got {len(cfs)}")
        camera_frames = []
        for fi, cf in enumerate(cfs):
            wf = f"{w}.frames[{fi}]"
            cf = rd.obj(cf, wf)
            K = rd.matrix(rd.key(cf, "K", wf), 3, 3, f"{wf}.K")
            if K[0, 0] <= 0 or K[1, 1] <= 0 or not np.allclose(K[2], [0, 0, 1]) or K[1, 0] != 0:
                rd.fail(f"{wf}.K", "expected [[fx,s,cx],[0,fy,cy],[0,0,1]] with fx, fy > 0")
            lo, hi = FOCAL_RANGE
            if not (lo <= K[0, 0] <= hi and lo <= K[1, 1] <= hi):
                rd.fail(f"{wf}.K", f"fx, fy must lie in [{lo:g}, {hi:g}] pixels, got {K[0, 0]:g}, {K[1, 1]:g}")
            if np.abs(K[:2, [1, 2]]).max() > PRINCIPAL_MAX:
                rd.fail(f"{wf}.K", f"skew, cx and cy must lie within {PRINCIPAL_MAX:g} pixels")
            c2w = rd.matrix(rd.key(cf, "camera_to_world", wf), 4, 4, f"{wf}.camera_to_world")
            if not conventions.is_rigid(c2w):
                rd.fail(f"{wf}.camera_to_world", "not a rigid transform (rotation must be orthonormal, det +1)")
            if np.abs(c2w[:3, 3]).max() > COORD_MAX:
                rd.fail(f"{wf}.camera_to_world", f"position beyond {COORD_MAX:g} m")
            if "world_to_camera" in cf:
                w2c = rd.matrix(cf["world_to_camera"], 4, 4, f"{wf}.world_to_camera")
                scale = 1.0 + np.abs(c2w[:3, 3]).max()
                if not np.allclose(w2c @ c2w, np.eye(4), atol=1e-5 * scale):
                    rd.fail(f"{wf}.world_to_camera", "is not the inverse of camera_to_world")
            else:
                w2c = conventions.invert_rigid(c2w)
            recorded = None
            if cf.get("recorded_camera_to_world") is not None:
                recorded = rd.matrix(cf["recorded_camera_to_world"], 4, 4, f"{wf}.recorded_camera_to_world")
                if not conventions.is_rigid(recorded) or np.abs(recorded[:3, 3]).max() > COORD_MAX:
                    rd.fail(f"{wf}.recorded_camera_to_world", "not a rigid transform within "
                            f"{COORD_MAX:g} m (rotation orthonormal, det +1)")
            camera_frames.append(CameraFrame(
                K, c2w, w2c,
                rd.ref(cf.get("image"), f"{wf}.image"),
                rd.ref(cf.get("depth"), f"{wf}.depth"), recorded))
        cameras.append(Camera(cname, width, height, camera_frames, depth_zero))
    if not cameras:
        rd.fail("cameras", "expected at least one camera")
    return cameras


def _actors(rd: _Reader, d: dict, nf: int) -> list[Actor]:
    actors = []
    for ai, a in enumerate(rd.lst(d.get("actors", []), "actors")):
        w = f"actors[{ai}]"
        a = rd.obj(a, w)
        aid = rd.name(rd.key(a, "id", w), f"{w}.id")
        if any(x.id == aid for x in actors):
            rd.fail(f"{w}.id", f"duplicate actor id {aid!r}")
        kind = rd.key(a, "kind", w)
        if kind not in ACTOR_KINDS:
            rd.fail(f"{w}.kind", f"expected one of {', '.join(ACTOR_KINDS)}, got {kind!r}")
        assets = rd.obj(rd.key(a, "assets", w), f"{w}.assets")
        splats = rd.ref(assets.get("splats"), f"{w}.assets.splats")
        mesh = rd.ref(assets.get("mesh"), f"{w}.assets.mesh")
        shadow = rd.ref(assets.get("shadow"), f"{w}.assets.shadow")
        if shadow is not None and kind != "existing":
            rd.fail(f"{w}.assets.shadow", "only an existing actor has a learnt shadow layer")
        wlh = None
        if a.get("wlh") is not None:
            wlh = rd.vector(a["wlh"], 3, f"{w}.wlh")
            if np.any(wlh <= 0):
                rd.fail(f"{w}.wlh", "sizes must be positive metres")
            if np.any(wlh > WLH_MAX):
                rd.fail(f"{w}.wlh", f"sizes must be at most {WLH_MAX:g} m, got {', '.join(f'{v:g}' for v in wlh)}")
        if splats is None and mesh is None and (kind == "inserted" or wlh is None):
            rd.fail(f"{w}.assets", "expected a splat PLY and/or a mesh path (an existing actor without them "
                                   "needs its wlh: the reconstruction fits it in its box)")
        poses = _pose_list(rd, rd.key(a, "poses", w), f"{w}.poses", nf)
        recorded = None
        if a.get("recorded_poses") is not None:
            if kind != "existing":
                rd.fail(f"{w}.recorded_poses", "only an existing actor has recorded poses")
            recorded = _pose_list(rd, a["recorded_poses"], f"{w}.recorded_poses", nf)
        tracked = None
        if a.get("tracked_poses") is not None:
            if kind != "existing":
                rd.fail(f"{w}.tracked_poses", "only an existing actor has tracked poses")
            tracked = _pose_list(rd, a["tracked_poses"], f"{w}.tracked_poses", nf)
        iid = rd.integer(a.get("instance_id", ai + 1), f"{w}.instance_id", 1, ID_MAX)
        if any(x.instance_id == iid for x in actors):
            rd.fail(f"{w}.instance_id", f"duplicate instance id {iid}")
        actors.append(Actor(aid, kind, splats, mesh, poses, wlh, iid, recorded, tracked, shadow))
    return actors


def _pose_list(rd: _Reader, value, w: str, nf: int) -> list[Pose | None]:
    plist = rd.lst(value, w)
    if len(plist) != nf:
        rd.fail(w, f"expected {nf} entries (one per frame, null where absent), got {len(plist)}")
    poses: list[Pose | None] = []
    for pi, p in enumerate(plist):
        wp = f"{w}[{pi}]"
        if p is None:
            poses.append(None)
            continue
        p = rd.obj(p, wp)
        t = rd.vector(rd.key(p, "translation", wp), 3, f"{wp}.translation")
        if np.abs(t).max() > COORD_MAX:
            rd.fail(f"{wp}.translation", f"beyond {COORD_MAX:g} m")
        q = rd.vector(rd.key(p, "rotation", wp), 4, f"{wp}.rotation")
        norm = np.linalg.norm(q)
        if norm < 1e-8:
            rd.fail(f"{wp}.rotation", "zero quaternion (expected unit w, x, y, z)")
        poses.append(Pose(t, q / norm))
    return poses


def _masks(rd: _Reader, d: dict, cam_names: set, actor_ids: set, nf: int) -> tuple[list[MaskEntry], list[IdMap]]:
    masks_obj = rd.obj(d.get("masks", {}), "masks")
    masks = []
    for mi, m in enumerate(rd.lst(masks_obj.get("entries", []), "masks.entries")):
        w = f"masks.entries[{mi}]"
        m = rd.obj(m, w)
        cam = rd.string(rd.key(m, "camera", w), f"{w}.camera")
        if cam not in cam_names:
            rd.fail(f"{w}.camera", f"no camera named {cam!r}")
        fr = rd.integer(rd.key(m, "frame", w), f"{w}.frame", 0)
        if fr >= nf:
            rd.fail(f"{w}.frame", f"frame {fr} out of range (package has {nf})")
        act = rd.string(rd.key(m, "actor", w), f"{w}.actor")
        if act not in actor_ids:
            rd.fail(f"{w}.actor", f"no actor with id {act!r}")
        masks.append(MaskEntry(cam, fr, act,
                               rd.ref(m.get("amodal"), f"{w}.amodal"),
                               rd.ref(m.get("visible"), f"{w}.visible")))
    id_maps = []
    for mi, m in enumerate(rd.lst(masks_obj.get("id_maps", []), "masks.id_maps")):
        w = f"masks.id_maps[{mi}]"
        m = rd.obj(m, w)
        cam = rd.string(rd.key(m, "camera", w), f"{w}.camera")
        if cam not in cam_names:
            rd.fail(f"{w}.camera", f"no camera named {cam!r}")
        fr = rd.integer(rd.key(m, "frame", w), f"{w}.frame", 0)
        if fr >= nf:
            rd.fail(f"{w}.frame", f"frame {fr} out of range (package has {nf})")
        ids = {}
        for k, v in rd.obj(rd.key(m, "ids", w), f"{w}.ids").items():
            if not (k.isascii() and k.isdigit() and len(k) <= 5) or not 0 < int(k) <= ID_MAX:
                rd.fail(f"{w}.ids", f"keys are positive integer ids (1..{ID_MAX}) as strings, got {k!r}")
            if v not in actor_ids:
                rd.fail(f"{w}.ids.{k}", f"no actor with id {v!r}")
            ids[int(k)] = v
        id_maps.append(IdMap(cam, fr, rd.ref(rd.key(m, "path", w), f"{w}.path", allow_none=False), ids))
    return masks, id_maps


def _effects(rd: _Reader, d: dict) -> Effects:
    e = rd.obj(d.get("effects", {}), "effects")
    offsets = [rd.num(v, f"effects.lateral_offsets[{i}]", OFFSET_MAX)
               for i, v in enumerate(rd.lst(e.get("lateral_offsets", []), "effects.lateral_offsets"))]
    sun = None
    if e.get("sun_direction") is not None:
        sun = rd.vector(e["sun_direction"], 3, "effects.sun_direction")
        n = np.linalg.norm(sun)
        if n < 1e-9:
            rd.fail("effects.sun_direction", "zero vector (omit it or use null for no sun)")
        sun = sun / n
    ratio = None
    if e.get("shadow_ratio") is not None:
        ratio = rd.num(e["shadow_ratio"], "effects.shadow_ratio")
        if not 0.0 <= ratio <= 1.0:
            rd.fail("effects.shadow_ratio", f"must lie in [0, 1] (fraction of light kept in shadow), got {ratio}")
    return Effects(offsets, rd.boolean(e.get("harmonize", False), "effects.harmonize"),
                      rd.boolean(e.get("finetune", False), "effects.finetune"),
                      rd.boolean(e.get("shadows", False), "effects.shadows"), sun, ratio)


def _source(rd: _Reader, d: dict) -> dict:
    source = rd.obj(d.get("source", {}), "source")
    if "transform" in source:
        T = rd.matrix(source["transform"], 4, 4, "source.transform")
        det = np.linalg.det(T[:3, :3])
        if not np.allclose(T[3], [0, 0, 0, 1]) or det <= 0 or not conventions.is_rigid(
                np.vstack([np.hstack([T[:3, :3] / np.cbrt(det), T[:3, 3:]]), [0, 0, 0, 1]])):
            rd.fail("source.transform", "not a similarity (scaled rotation, positive scale, last row 0 0 0 1)")
    return source


def parse_manifest(data: Any, path: Path, *, allow_external: bool = False) -> Manifest:
    """A :class:`Manifest` from parsed JSON: the schema first (every key, type and range), then per
    section what a schema cannot say (``path``: the file it came from, whose folder is the package
    root; ``allow_external``: asset paths may lead outside it)."""
    rd = _Reader(path)
    _check_depth(rd, data)  # before the schema, whose validator recurses
    for where, message in (schema_problems(data) or [])[:1]:
        rd.fail(where, message)
    d = rd.obj(data, "(root)")
    if d.get("format", FORMAT) != FORMAT:
        rd.fail("format", f"expected {FORMAT!r}, got {d.get('format')!r}")
    version = rd.integer(rd.key(d, "version", ""), "version")
    if version != VERSION:
        rd.fail("version", f"this reader understands version {VERSION}, got {version}")
    name = rd.name(rd.key(d, "name", ""), "name")
    frames = _frames(rd, d)
    nf = len(frames)
    cameras = _cameras(rd, d, nf)
    actors = _actors(rd, d, nf)
    cam_names = {c.name for c in cameras}
    masks, id_maps = _masks(rd, d, cam_names, {a.id for a in actors}, nf)
    effects = _effects(rd, d)
    gt = rd.obj(d.get("ground_truth", {}), "ground_truth")
    _check_ground_truth_refs(rd, gt, cam_names, nf)
    bg = rd.obj(d.get("background", {}), "background")
    _warn_if_far(path, cameras)
    return Manifest(
        name=name, frames=frames, cameras=cameras, actors=actors,
        background_splats=rd.ref(bg.get("splats"), "background.splats"),
        background_points=rd.ref(bg.get("points"), "background.points"),
        masks=masks, id_maps=id_maps, effects=effects,
        output=rd.output(d.get("output", "output")), ground_truth=gt, source=_source(rd, d),
        root=path.parent, path=path, allow_external=allow_external)


def _warn_if_far(path: Path, cameras: list[Camera]) -> None:
    far = max((float(np.abs(cf.camera_to_world[:3, 3]).max()) for c in cameras for cf in c.frames), default=0.0)
    if far > FLOAT32_NEAR_M:
        step = float(np.spacing(np.float32(far)))
        warnings.warn(f"{path}: cameras up to {far:.0f} m from the origin, where the splats' float32 positions step "
                      f"by {100 * step:.0f} cm: renders and fits lose detail; move the origin near the drive (the "
                      "importers' local frame does)", stacklevel=3)


def load_manifest(path: str | os.PathLike, *, allow_external: bool = False) -> Manifest:
    """Load and validate ``manifest.json`` (or a package directory containing one).

    ``allow_external``: asset paths may lead outside the package (absolute paths, ``..``,
    symlinks out), as ``--allow-external-assets`` asks; otherwise :meth:`Manifest.resolve` and
    :func:`check_files` refuse them.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "manifest.json"
    with open_regular(path) as f:
        raw = f.read(MANIFEST_BYTES_MAX + 1)
    if len(raw) > MANIFEST_BYTES_MAX:
        raise ManifestError(path, f"larger than {MANIFEST_BYTES_MAX} bytes: not a manifest")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ManifestError(path, f"not UTF-8 text (byte {exc.start})") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ManifestError(path, f"not valid JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}") from None
    except RecursionError:
        raise ManifestError(path, f"not a manifest: JSON nested deeper than {JSON_DEPTH_MAX} levels") from None
    except ValueError as exc:  # e.g. an integer literal with thousands of digits
        raise ManifestError(path, f"not valid JSON: {exc}") from None
    return parse_manifest(data, path, allow_external=allow_external)


# What an asset file's header is checked against: how each field's files are read.
_MESH_SUFFIXES = (".obj", ".glb", ".gltf", ".ply")
_OBJ_KEYWORDS = {b"v", b"vn", b"vt", b"vp", b"f", b"l", b"p", b"o", b"g", b"s", b"mtllib", b"usemtl"}


def _check_shadow(path: Path) -> None:
    """A shadow layer reads as one (a small file: read whole)."""
    from ..io import check_regular
    from ..io.shadow_grid import read_shadow_grid

    check_regular(path)
    try:
        read_shadow_grid(path)
    except ValueError as exc:
        raise InputError(path, str(exc), "shadow") from None


def _check_mesh(path: Path) -> None:
    """A mesh is non-empty and recognisable as OBJ, glTF (binary or JSON) or PLY; only its
    first bytes are read."""
    from ..io import check_regular

    st = check_regular(path)
    if st.st_size == 0:
        raise InputError(path, "empty file", "mesh")
    with open_regular(path) as f:
        head = f.read(64 * 1024)
    suffix = path.suffix.lower()
    if head.startswith(b"glTF"):
        return
    if head.startswith(b"ply"):
        from ..io.ply import read_header

        header = read_header(path)
        if header.element("vertex") is None:
            raise InputError(path, "PLY mesh has no 'vertex' element", "element vertex")
        return
    if suffix == ".gltf" and head.lstrip().startswith(b"{"):
        return
    if suffix in (".obj", "") or suffix not in _MESH_SUFFIXES:
        for line in head.splitlines()[:-1] or head.splitlines():
            words = line.split()
            if not words or words[0].startswith(b"#"):
                continue
            if words[0] in _OBJ_KEYWORDS:
                return
            break
    raise InputError(path, "not a mesh this reader recognises (OBJ, glTF/GLB or PLY)", "mesh")


def _check_image(path: Path, size: tuple[int, int] | None) -> None:
    """An image's header (no pixels decoded), and its size against the camera's."""
    try:
        from ..io.images import image_size

        width, height, _ = image_size(path)
    except ImportError:  # no OpenImageIO here: a regular, non-empty file at least
        from ..io import check_regular

        if check_regular(path).st_size == 0:
            raise InputError(path, "empty file") from None
        return
    if size is not None and (width, height) != size:
        raise InputError(path, f"image is {width}x{height}, the camera is {size[0]}x{size[1]}")


def check_files(m: Manifest, *, headers: bool = True) -> None:
    """Every file the manifest names lies inside the package (unless it was loaded with
    ``allow_external``), exists, and (``headers``) has a header that fits: PLY header and
    vertex count against the file size, image header and size against the camera's, mesh
    header. No data is loaded. ``symdrive validate`` and ``symdrive run`` run this."""
    sizes = {c.name: (c.width, c.height) for c in m.cameras}
    kinds: dict[str, tuple[str, tuple[int, int] | None]] = {
        "background.splats": ("splats", None), "background.points": ("points", None)}
    for ci, c in enumerate(m.cameras):
        for fi in range(len(c.frames)):
            for key in ("image", "depth"):
                kinds[f"cameras[{ci}].frames[{fi}].{key}"] = ("image", sizes[c.name])
    for ai in range(len(m.actors)):
        kinds[f"actors[{ai}].assets.splats"] = ("splats", None)
        kinds[f"actors[{ai}].assets.mesh"] = ("mesh", None)
        kinds[f"actors[{ai}].assets.shadow"] = ("shadow", None)
    for mi, e in enumerate(m.masks):
        for key in ("amodal", "visible"):
            kinds[f"masks.entries[{mi}].{key}"] = ("image", sizes.get(e.camera))
    for mi, e in enumerate(m.id_maps):
        kinds[f"masks.id_maps[{mi}].path"] = ("image", sizes.get(e.camera))
    where_file = m.path or m.root
    refs = m.asset_refs()
    for where, rel, camera in m.ground_truth_refs():
        refs.append((where, rel))
        kinds[where] = ("image", sizes.get(camera))
    for where, rel in refs:
        full = m.resolve(rel, where)
        if not full.exists():
            raise ManifestError(where_file, f"file not found: {rel}", where)
        if not headers:
            continue
        kind, size = kinds.get(where, ("", None))
        try:
            if kind in ("splats", "points"):
                from ..io.ply import check_ply

                check_ply(full, kind)
            elif kind == "mesh":
                _check_mesh(full)
            elif kind == "shadow":
                _check_shadow(full)
            elif kind == "image":
                _check_image(full, size)
        except InputError as exc:
            detail = f"{exc.field}: {exc.message}" if exc.field else exc.message
            raise ManifestError(where_file, f"{rel}: {detail}", where) from None
