"""Scene package: ``manifest.json`` loaded into typed objects, validated field by field.

A scene package is a directory with ``manifest.json`` and the files it names (paths relative
to the manifest). Every error names the JSON field path, e.g.
``actors[2].poses[17].rotation: expected 4 numbers``. numpy only (the add-on writes these).
The JSON Schema in ``manifest.schema.json`` describes the same format for other tools.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import conventions
from ..errors import InputError
from ..io.atomic import write_text_atomic
from .poses import Pose

FORMAT = "symdrive-scene"
VERSION = 1
ACTOR_KINDS = ("existing", "inserted")
SCHEMA_PATH = Path(__file__).with_name("manifest.schema.json")


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


@dataclass
class Camera:
    name: str
    width: int
    height: int
    frames: list[CameraFrame]


@dataclass
class Actor:
    id: str
    kind: str  # "existing" | "inserted"
    splats: str | None
    mesh: str | None
    poses: list[Pose | None]  # one per frame; None = not in the scene in that frame
    wlh: np.ndarray | None = None
    instance_id: int = 0  # 1-based id used in id-map masks and instance channels

    def pose(self, frame: int) -> Pose | None:
        return self.poses[frame]


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
    root: Path = field(default_factory=Path.cwd)
    path: Path | None = None

    def resolve(self, rel: str | None) -> Path | None:
        return None if rel is None else (self.root / rel)

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

    def file_refs(self) -> list[tuple[str, str]]:
        """Every file the manifest names, as (field, path as written)."""
        refs: list[tuple[str, str | None]] = [("background.splats", self.background_splats),
                                              ("background.points", self.background_points)]
        for ci, c in enumerate(self.cameras):
            for fi, cf in enumerate(c.frames):
                refs += [(f"cameras[{ci}].frames[{fi}].image", cf.image),
                         (f"cameras[{ci}].frames[{fi}].depth", cf.depth)]
        for ai, a in enumerate(self.actors):
            refs += [(f"actors[{ai}].assets.splats", a.splats), (f"actors[{ai}].assets.mesh", a.mesh)]
        for mi, e in enumerate(self.masks):
            refs += [(f"masks.entries[{mi}].amodal", e.amodal), (f"masks.entries[{mi}].visible", e.visible)]
        for mi, e in enumerate(self.id_maps):
            refs.append((f"masks.id_maps[{mi}].path", e.path))
        return [(where, rel) for where, rel in refs if rel is not None]

    def to_json(self) -> dict:
        def camera_frame(cf: CameraFrame) -> dict:
            d = {"K": cf.K.tolist(), "camera_to_world": cf.camera_to_world.tolist(),
                 "world_to_camera": cf.world_to_camera.tolist()}
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
                         "frames": [camera_frame(cf) for cf in c.frames]} for c in self.cameras],
            "background": {"splats": self.background_splats, "points": self.background_points},
            "actors": [{
                "id": a.id, "kind": a.kind, "instance_id": a.instance_id,
                "assets": {"splats": a.splats, "mesh": a.mesh},
                **({"wlh": [float(v) for v in a.wlh]} if a.wlh is not None else {}),
                "poses": [None if p is None else p.to_json() for p in a.poses],
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
        return out

    def save(self, path: str | os.PathLike | None = None) -> Path:
        path = Path(path) if path is not None else (self.path or self.root / "manifest.json")
        write_text_atomic(path, json.dumps(self.to_json(), indent=1) + "\n")
        return path


# ---------------------------------------------------------------- parsing with field paths


class _Reader:
    def __init__(self, path: Path):
        self.path = path

    def fail(self, where: str, message: str):
        raise ManifestError(self.path, message, where)

    def obj(self, v, where) -> dict:
        if not isinstance(v, dict):
            self.fail(where, f"expected an object, got {type(v).__name__}")
        return v

    def key(self, d: dict, k: str, where: str, default=...):
        if k not in d:
            if default is ...:
                self.fail(f"{where}.{k}" if where else k, "required field is missing")
            return default
        return d[k]

    def lst(self, v, where) -> list:
        if not isinstance(v, list):
            self.fail(where, f"expected a list, got {type(v).__name__}")
        return v

    def num(self, v, where) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
            self.fail(where, f"expected a finite number, got {v!r}")
        return float(v)

    def integer(self, v, where, minimum=None) -> int:
        if isinstance(v, bool) or not isinstance(v, int):
            self.fail(where, f"expected an integer, got {v!r}")
        if minimum is not None and v < minimum:
            self.fail(where, f"expected an integer >= {minimum}, got {v}")
        return v

    def string(self, v, where, allow_none=False) -> str | None:
        if v is None and allow_none:
            return None
        if not isinstance(v, str) or not v:
            self.fail(where, f"expected a non-empty string, got {v!r}")
        return v

    def boolean(self, v, where) -> bool:
        if not isinstance(v, bool):
            self.fail(where, f"expected true or false, got {v!r}")
        return v

    def vector(self, v, n, where) -> np.ndarray:
        if (not isinstance(v, list) or len(v) != n
                or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in v)):
            self.fail(where, f"expected {n} numbers")
        a = np.asarray(v, dtype=np.float64)
        if not np.all(np.isfinite(a)):
            self.fail(where, "expected finite numbers")
        return a

    def matrix(self, v, r, c, where) -> np.ndarray:
        if not isinstance(v, list) or len(v) != r:
            self.fail(where, f"expected a {r}x{c} matrix (list of {r} rows)")
        return np.stack([self.vector(row, c, f"{where}[{i}]") for i, row in enumerate(v)])


def _rigid_ok(M: np.ndarray) -> bool:
    R = M[:3, :3]
    return (np.allclose(R @ R.T, np.eye(3), atol=1e-4) and abs(np.linalg.det(R) - 1) < 1e-4
            and np.allclose(M[3], [0, 0, 0, 1]))


def parse_manifest(data: Any, path: Path) -> Manifest:
    rd = _Reader(path)
    d = rd.obj(data, "(root)")
    if d.get("format", FORMAT) != FORMAT:
        rd.fail("format", f"expected {FORMAT!r}, got {d.get('format')!r}")
    version = rd.integer(rd.key(d, "version", ""), "version")
    if version != VERSION:
        rd.fail("version", f"this reader understands version {VERSION}, got {version}")
    name = rd.string(rd.key(d, "name", ""), "name")

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
    nf = len(frames)

    cameras = []
    for ci, c in enumerate(rd.lst(rd.key(d, "cameras", ""), "cameras")):
        w = f"cameras[{ci}]"
        c = rd.obj(c, w)
        cname = rd.string(rd.key(c, "name", w), f"{w}.name")
        if any(x.name == cname for x in cameras):
            rd.fail(f"{w}.name", f"duplicate camera name {cname!r}")
        width = rd.integer(rd.key(c, "width", w), f"{w}.width", 1)
        height = rd.integer(rd.key(c, "height", w), f"{w}.height", 1)
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
            c2w = rd.matrix(rd.key(cf, "camera_to_world", wf), 4, 4, f"{wf}.camera_to_world")
            if not _rigid_ok(c2w):
                rd.fail(f"{wf}.camera_to_world", "not a rigid transform (rotation must be orthonormal, det +1)")
            if "world_to_camera" in cf:
                w2c = rd.matrix(cf["world_to_camera"], 4, 4, f"{wf}.world_to_camera")
                scale = 1.0 + np.abs(c2w[:3, 3]).max()
                if not np.allclose(w2c @ c2w, np.eye(4), atol=1e-5 * scale):
                    rd.fail(f"{wf}.world_to_camera", "is not the inverse of camera_to_world")
            else:
                w2c = conventions.invert_rigid(c2w)
            camera_frames.append(CameraFrame(
                K, c2w, w2c,
                rd.string(cf.get("image"), f"{wf}.image", allow_none=True),
                rd.string(cf.get("depth"), f"{wf}.depth", allow_none=True)))
        cameras.append(Camera(cname, width, height, camera_frames))
    if not cameras:
        rd.fail("cameras", "expected at least one camera")

    bg = rd.obj(d.get("background", {}), "background")
    actors = []
    for ai, a in enumerate(rd.lst(d.get("actors", []), "actors")):
        w = f"actors[{ai}]"
        a = rd.obj(a, w)
        aid = rd.string(rd.key(a, "id", w), f"{w}.id")
        if any(x.id == aid for x in actors):
            rd.fail(f"{w}.id", f"duplicate actor id {aid!r}")
        kind = rd.key(a, "kind", w)
        if kind not in ACTOR_KINDS:
            rd.fail(f"{w}.kind", f"expected one of {', '.join(ACTOR_KINDS)}, got {kind!r}")
        assets = rd.obj(rd.key(a, "assets", w), f"{w}.assets")
        splats = rd.string(assets.get("splats"), f"{w}.assets.splats", allow_none=True)
        mesh = rd.string(assets.get("mesh"), f"{w}.assets.mesh", allow_none=True)
        if splats is None and mesh is None:
            rd.fail(f"{w}.assets", "expected a splat PLY and/or a mesh path")
        wlh = None
        if a.get("wlh") is not None:
            wlh = rd.vector(a["wlh"], 3, f"{w}.wlh")
            if np.any(wlh <= 0):
                rd.fail(f"{w}.wlh", "sizes must be positive metres")
        plist = rd.lst(rd.key(a, "poses", w), f"{w}.poses")
        if len(plist) != nf:
            rd.fail(f"{w}.poses", f"expected {nf} entries (one per frame, null where absent), got {len(plist)}")
        poses: list[Pose | None] = []
        for pi, p in enumerate(plist):
            wp = f"{w}.poses[{pi}]"
            if p is None:
                poses.append(None)
                continue
            p = rd.obj(p, wp)
            t = rd.vector(rd.key(p, "translation", wp), 3, f"{wp}.translation")
            q = rd.vector(rd.key(p, "rotation", wp), 4, f"{wp}.rotation")
            norm = np.linalg.norm(q)
            if norm < 1e-8:
                rd.fail(f"{wp}.rotation", "zero quaternion (expected unit w, x, y, z)")
            poses.append(Pose(t, q / norm))
        iid = rd.integer(a.get("instance_id", ai + 1), f"{w}.instance_id", 1)
        if any(x.instance_id == iid for x in actors):
            rd.fail(f"{w}.instance_id", f"duplicate instance id {iid}")
        actors.append(Actor(aid, kind, splats, mesh, poses, wlh, iid))

    cam_names = {c.name for c in cameras}
    actor_ids = {a.id for a in actors}
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
                               rd.string(m.get("amodal"), f"{w}.amodal", allow_none=True),
                               rd.string(m.get("visible"), f"{w}.visible", allow_none=True)))
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
            if not k.isdigit() or int(k) == 0:
                rd.fail(f"{w}.ids", f"keys are positive integer ids as strings, got {k!r}")
            if v not in actor_ids:
                rd.fail(f"{w}.ids.{k}", f"no actor with id {v!r}")
            ids[int(k)] = v
        id_maps.append(IdMap(cam, fr, rd.string(rd.key(m, "path", w), f"{w}.path"), ids))

    e = rd.obj(d.get("effects", {}), "effects")
    offsets = [rd.num(v, f"effects.lateral_offsets[{i}]")
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
    effects = Effects(offsets, rd.boolean(e.get("harmonize", False), "effects.harmonize"),
                      rd.boolean(e.get("finetune", False), "effects.finetune"),
                      rd.boolean(e.get("shadows", False), "effects.shadows"), sun, ratio)
    gt = rd.obj(d.get("ground_truth", {}), "ground_truth")
    return Manifest(
        name=name, frames=frames, cameras=cameras, actors=actors,
        background_splats=rd.string(bg.get("splats"), "background.splats", allow_none=True),
        background_points=rd.string(bg.get("points"), "background.points", allow_none=True),
        masks=masks, id_maps=id_maps, effects=effects,
        output=rd.string(d.get("output", "output"), "output"), ground_truth=gt,
        root=path.parent, path=path)


def load_manifest(path: str | os.PathLike, *, allow_external: bool = False) -> Manifest:
    """Load and validate ``manifest.json`` (or a package directory containing one)."""
    path = Path(path)
    if path.is_dir():
        path = path / "manifest.json"
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ManifestError(path, f"cannot read: {exc.strerror}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ManifestError(path, f"not valid JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}") from None
    return parse_manifest(data, path)


def check_files(m: Manifest) -> None:
    """Every file the manifest names exists (``symdrive validate`` runs this too)."""
    for where, rel in m.file_refs():
        if not (m.root / rel).exists():
            raise ManifestError(m.path or m.root, f"file not found: {rel}", where)
