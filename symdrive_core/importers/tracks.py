"""Tracks of recorded vehicles -> ``existing`` actors of a package (``symdrive import tracks``).

A recorded drive's vehicles are where its reconstruction must put (and a removal take out)
actors of kind ``existing``: each track becomes one actor whose pose in each package frame is the
track's box there (``None`` where it has none), in the 3DRealCar frame (X forward along the
length, Y left, Z up, origin at the box centre), with the track's size as ``wlh``, no assets yet
(the reconstruction fills them) and instance ids after the largest in the package.

Two formats, told apart by the file's suffix (``.json``, ``.txt``) unless given:

- **JSON**::

    {"frame": "world" | "source" | "camera",
     "tracks": [{"id": "car_3", "w": 1.8, "l": 4.5, "h": 1.5,
                 "boxes": [{"frame": 0, "centre": [x, y, z], "yaw": 0.3},
                           {"frame": 1, "centre": [x, y, z], "quaternion": [w, x, y, z]}]}]}

  ``frame`` is the boxes' coordinate frame. ``world``: the package's world (metres, Z up);
  ``centre`` is the box centre, ``yaw`` turns the box about Z (0: length along +X) and
  ``quaternion`` is the rotation of the 3DRealCar axes. ``source``: the frame the drive's poses
  came in, mapped to the world by the package's ``source.poses_transform`` (nerfstudio's frame of
  ``transforms.json``), else ``source.transform``; the same as ``world`` in that frame (``yaw``
  about its z axis: give a quaternion when its z is not up), and the similarity's scale applies to
  centres and sizes. ``camera``: OpenCV coordinates of the package camera (``--camera``, default the
  first) at the box's frame (x right, y down, z forward, metres), as KITTI writes them: ``centre``
  is the box's *bottom* centre, ``yaw`` is KITTI's ``rotation_y`` about the camera's y (0: length
  along +x) and ``quaternion`` the rotation of KITTI's object axes (x along the length, y down,
  z to the vehicle's left), of which ``rotation_y`` is the special case ``R_y``. ``id`` is a
  plain name (the actor's id); each box has ``yaw`` or ``quaternion``, not both; a box's ``frame``
  is a package frame index.
- **KITTI tracking labels** (``label_02/NNNN.txt``), one box per line: ``frame track_id type
  truncated occluded alpha x1 y1 x2 y2 h w l x y z rotation_y [score]``, in metres in KITTI's
  rectified camera 0 frame with ``x y z`` the bottom centre. A package imported from colour
  images has camera 2 as its camera, which sits ``-K^-1 P2[:, 3]`` from camera 0 (6 cm):
  ``--calib`` with the sequence's calibration file moves the boxes there; without it they are
  taken in the package camera's frame. Lines of types not kept (default Car, Van, Truck) and
  ``DontCare`` are skipped and counted; a track's size is its median box, its actor is
  ``track_<track_id>`` and each box keeps its bottom where the label puts it.

A box's frame minus ``frame_offset`` is its package frame (a package may be a window of a
sequence); boxes outside the package's frames are counted, not imported. Input is checked whole
before the manifest is written (atomically): bad input is an :class:`InputError` naming the file
and the field (``tracks[2].boxes[5].yaw``, ``line 17``) and leaves the package as it was.
"""

from __future__ import annotations

import json
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import check_regular, open_regular
from ..rotations import quat_to_matrix
from ..scene.fields import FieldReader
from ..scene.manifest import COORD_MAX, ID_MAX, WLH_MAX, Actor, parse_manifest
from ..scene.paths import check_name
from ..scene.poses import Pose
from .calib_text import finite_numbers
from .kitti import camera_offset
from .similarity import decompose
from .track_checks import TrackChecks, check_track, in_view

TRACK_FORMATS = ("json", "kitti")
TRACK_FRAMES = ("world", "source", "camera")
TRACKS_BYTES_MAX = 256 * 1024 * 1024
KITTI_FIELDS = "frame track_id type truncated occluded alpha x1 y1 x2 y2 h w l x y z rotation_y [score]"
# KITTI's object axes (x along the length, y down, z to the vehicle's left) of the 3DRealCar axes
# (X forward, Y left, Z up): the columns are X, Y, Z written in KITTI's axes.
KITTI_FROM_VEHICLE = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@dataclass(frozen=True)
class TracksConfig:
    # KITTI object types imported as vehicles (DontCare never is).
    types: tuple[str, ...] = ("Car", "Van", "Truck")
    # A box's frame minus this is its package frame.
    frame_offset: int = 0
    # What a track's consecutive boxes may do before a frame is reported (a jump, a turn, ...).
    checks: TrackChecks = TrackChecks()


@dataclass
class Box:
    frame: int  # as the file numbers it
    centre: np.ndarray  # [3] box centre in the tracks' frame
    rotation: np.ndarray  # [3, 3] the 3DRealCar axes in the tracks' frame
    where: str  # the field, for messages
    wlh: np.ndarray | None = None  # the box's own size where the tracks give one per box (KITTI)


@dataclass
class Track:
    id: str
    wlh: np.ndarray  # [3] in the tracks' frame's units
    boxes: list[Box]
    where: str  # the field of its id
    size_where: tuple[str, str, str]  # the fields of w, l, h


@dataclass
class Tracks:
    path: Path
    frame: str  # one of TRACK_FRAMES
    tracks: list[Track]
    skipped: dict[str, int] = field(default_factory=dict)  # KITTI lines not imported, by type


# ---------------------------------------------------------------- box conventions


def _yaw_z(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _kitti_r_y(rotation_y: float) -> np.ndarray:
    """KITTI's rotation of a box about the camera's y (the devkit's ``R``)."""
    c, s = np.cos(rotation_y), np.sin(rotation_y)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _from_kitti_axes(bottom: np.ndarray, rotation: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """(box centre, 3DRealCar axes) of a box given KITTI's way: its bottom centre and the rotation
    of its object axes. The centre is the bottom raised by h/2 along the box's up (-y)."""
    return bottom + rotation @ np.array([0.0, -h / 2.0, 0.0]), rotation @ KITTI_FROM_VEHICLE


# ---------------------------------------------------------------- JSON


class _Fields(FieldReader):
    """The manifest's field reader with a closed object (unknown keys refused), element-wise
    named vectors and frame indices."""

    def closed_obj(self, v, where: str, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> dict:
        v = self.obj(v, where)
        for k in required:
            self.key(v, k, where)
        for k in v:
            if k not in required + optional:
                self.fail(f"{where}.{k}" if where else str(k), "unknown field")
        return v

    def vector(self, v, n: int, where: str) -> np.ndarray:
        if not isinstance(v, list) or len(v) != n:
            self.fail(where, f"expected {n} numbers")
        return np.array([self.num(x, f"{where}[{i}]") for i, x in enumerate(v)])

    def frame(self, v, where: str) -> int:
        if isinstance(v, bool) or not isinstance(v, int) or v < 0:
            self.fail(where, f"expected a frame index (an integer >= 0), got {v!r}")
        return v


def _check_size(fields: _Fields, value: float, where: str) -> float:
    if not 0.0 < value <= WLH_MAX:
        fields.fail(where, f"expected a size in (0, {WLH_MAX:g}] metres, got {value:g}")
    return value


def _check_centre(fields: _Fields, centre: np.ndarray, where: str) -> np.ndarray:
    if np.abs(centre).max() > COORD_MAX:
        fields.fail(where, f"beyond {COORD_MAX:g} m")
    return centre


def _json_rotation(fields: _Fields, box: dict, where: str, frame: str) -> np.ndarray:
    """The box's rotation as written (about z, or KITTI's y in the camera frame)."""
    if ("yaw" in box) == ("quaternion" in box):
        fields.fail(where, "expected one of yaw or quaternion")
    if "yaw" in box:
        yaw = fields.num(box["yaw"], f"{where}.yaw")
        return _kitti_r_y(yaw) if frame == "camera" else _yaw_z(yaw)
    q = fields.vector(box["quaternion"], 4, f"{where}.quaternion")
    if np.linalg.norm(q) < 1e-8:
        fields.fail(f"{where}.quaternion", "zero quaternion (expected unit w, x, y, z)")
    return quat_to_matrix(q)


def _json_track(fields: _Fields, t, where: str, frame: str) -> Track:
    t = fields.closed_obj(t, where, ("id", "w", "l", "h", "boxes"))
    tid = check_name(t["id"], f"{where}.id", fields.path)
    wlh = np.array([_check_size(fields, fields.num(t[k], f"{where}.{k}"), f"{where}.{k}") for k in "wlh"])
    boxes, seen = [], set()
    for j, b in enumerate(fields.lst(t["boxes"], f"{where}.boxes")):
        wb = f"{where}.boxes[{j}]"
        b = fields.closed_obj(b, wb, ("frame", "centre"), ("yaw", "quaternion"))
        fi = fields.frame(b["frame"], f"{wb}.frame")
        if fi in seen:
            fields.fail(f"{wb}.frame", f"track {tid!r} has a box in frame {fi} already")
        seen.add(fi)
        centre = _check_centre(fields, fields.vector(b["centre"], 3, f"{wb}.centre"), f"{wb}.centre")
        rotation = _json_rotation(fields, b, wb, frame)
        if frame == "camera":
            centre, rotation = _from_kitti_axes(centre, rotation, wlh[2])
        boxes.append(Box(fi, centre, rotation, wb))
    if not boxes:
        fields.fail(f"{where}.boxes", f"track {tid!r} has no boxes: no frame says where it is")
    return Track(tid, wlh, boxes, f"{where}.id", tuple(f"{where}.{k}" for k in "wlh"))


def _load_json(path: Path):
    with open_regular(path, "TRACKS_FILE") as f:
        raw = f.read(TRACKS_BYTES_MAX + 1)
    if len(raw) > TRACKS_BYTES_MAX:
        raise InputError(path, f"larger than {TRACKS_BYTES_MAX} bytes: not a tracks file")
    try:
        return json.loads(raw.decode("utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise InputError(path, f"not UTF-8 text (byte {exc.start})") from None
    except json.JSONDecodeError as exc:
        raise InputError(path, f"not valid JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}") from None
    except (RecursionError, ValueError) as exc:  # nesting beyond the parser, a number with thousands of digits
        raise InputError(path, f"not valid JSON: {type(exc).__name__}") from None


def read_tracks_json(path: Path) -> Tracks:
    """Tracks from the JSON format above, their boxes in 3DRealCar terms in the file's frame."""
    path = Path(path)
    fields = _Fields(path)
    d = fields.closed_obj(_load_json(path), "", ("frame", "tracks"))
    frame = d["frame"]
    if frame not in TRACK_FRAMES:
        fields.fail("frame", f"expected one of {', '.join(TRACK_FRAMES)}, got {frame!r}")
    tracks = []
    for i, t in enumerate(fields.lst(d["tracks"], "tracks")):
        track = _json_track(fields, t, f"tracks[{i}]", frame)
        if any(x.id == track.id for x in tracks):
            fields.fail(f"tracks[{i}].id", f"duplicate track id {track.id!r}")
        tracks.append(track)
    return Tracks(path, frame, tracks)


# ---------------------------------------------------------------- KITTI


@dataclass
class _Label:
    line: int
    frame: int
    hwl: np.ndarray
    bottom: np.ndarray
    rotation_y: float
    box2d: np.ndarray  # x1 y1 x2 y2: the annotator's box in the labelled image's pixels


def _label_int(text: str, path: Path, where: str, what: str, minimum: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise InputError(path, f"{what}: expected an integer, got {text!r}", where) from None
    if value < minimum:
        raise InputError(path, f"{what}: expected an integer >= {minimum}, got {value}", where)
    return value


def _read_label_lines(path: Path, types: tuple[str, ...]) -> tuple[dict[int, list[_Label]], Counter]:
    """The kept labels by track id (in order of appearance) and the skipped lines by type."""
    if check_regular(path, "TRACKS_FILE").st_size > TRACKS_BYTES_MAX:
        raise InputError(path, f"larger than {TRACKS_BYTES_MAX} bytes: not a label file")
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except UnicodeDecodeError as exc:
        raise InputError(path, f"not UTF-8 text (byte {exc.start})") from None
    tracks: dict[int, list[_Label]] = {}
    skipped: Counter = Counter()
    for n, line in enumerate(lines, start=1):
        words, where = line.split(), f"line {n}"
        if not words:
            continue
        if len(words) not in (17, 18):
            raise InputError(path, f"expected 17 or 18 fields ({KITTI_FIELDS}), got {len(words)}", where)
        frame = _label_int(words[0], path, where, "frame", 0)
        values = finite_numbers(" ".join(words[3:]), len(words) - 3, path, where)
        kind = words[2]
        if kind == "DontCare" or kind not in types:
            skipped[kind] += 1
            continue
        track = _label_int(words[1], path, where, "track_id", 0)
        hwl, bottom = values[7:10], values[10:13]
        if not np.all((hwl > 0) & (hwl <= WLH_MAX)):
            raise InputError(path, f"h, w, l must lie in (0, {WLH_MAX:g}] metres, got "
                                   f"{', '.join(f'{v:g}' for v in hwl)}", where)
        if np.abs(bottom).max() > COORD_MAX:
            raise InputError(path, f"x, y, z beyond {COORD_MAX:g} m", where)
        earlier = next((x.line for x in tracks.get(track, []) if x.frame == frame), None)
        if earlier is not None:
            raise InputError(path, f"track {track} has a box in frame {frame} already (line {earlier})", where)
        tracks.setdefault(track, []).append(_Label(n, frame, hwl, bottom, float(values[13]), values[3:7]))
    return tracks, skipped


def read_kitti_labels(path: Path, types: tuple[str, ...] = TracksConfig.types) -> Tracks:
    """Tracks from a KITTI tracking label file, boxes in 3DRealCar terms in the camera frame."""
    path = Path(path)
    labels, skipped = _read_label_lines(path, tuple(types))
    tracks = []
    for tid, rows in labels.items():
        h, w, length = np.median(np.stack([r.hwl for r in rows]), axis=0)
        boxes = [Box(r.frame, *_from_kitti_axes(r.bottom, _kitti_r_y(r.rotation_y), h), f"line {r.line}",
                     r.hwl[[1, 2, 0]]) for r in rows]
        first = f"line {rows[0].line}"
        tracks.append(Track(_track_name(tid), np.array([w, length, h]), boxes, first, (first,) * 3))
    return Tracks(path, "camera", tracks, dict(skipped))


def read_kitti_label_boxes(path: Path, types: tuple[str, ...] = TracksConfig.types) -> dict[str, dict[int, np.ndarray]]:
    """The labels' own 2D boxes (``x1 y1 x2 y2`` in the labelled image's pixels) by track, named
    as :func:`read_kitti_labels` names it, and frame: where the annotators saw each vehicle,
    drawn apart from its 3D box (what scores a real drive's moving vehicles)."""
    labels, _ = _read_label_lines(Path(path), tuple(types))
    return {_track_name(tid): {r.frame: r.box2d for r in rows} for tid, rows in labels.items()}


def _track_name(tid: int) -> str:
    return f"track_{tid}"


def read_camera_offset(path: Path) -> np.ndarray:
    """Where camera 2 sits in rectified camera 0's frame, from a KITTI calibration file's ``P2``
    (tracking ``calib/NNNN.txt``, odometry ``calib.txt``, object ``calib/NNNNNN.txt``)."""
    path = Path(path)
    if check_regular(path, "--calib").st_size > 1 << 20:
        raise InputError(path, "larger than 1 MB: not a calibration file", "--calib")
    for line in path.read_text(encoding="utf-8-sig", errors="replace").splitlines():
        label, _, rest = line.strip().partition(" ")
        if label.rstrip(":") == "P2":
            P = finite_numbers(rest, 12, path, "P2").reshape(3, 4)
            if not (P[0, 0] > 0 and P[1, 1] > 0 and np.allclose(P[2, :3], [0, 0, 1]) and P[1, 0] == 0):
                raise InputError(path, "not a rectified projection K [I | t]", "P2")
            return camera_offset(P)
    raise InputError(path, "no P2 line (camera 2's projection matrix)", "P2")


def tracks_format(path, fmt: str | None = None) -> str:
    """``fmt``, else the format the file's suffix names."""
    if fmt is not None:
        return fmt
    suffix = Path(path).suffix.lower()
    if suffix not in (".json", ".txt"):
        raise InputError(path, f"cannot tell the format from the suffix {suffix!r} (.json: JSON, .txt: KITTI "
                               "labels): pass --format", "--format")
    return "json" if suffix == ".json" else "kitti"


def read_tracks(path, fmt: str | None = None, config: TracksConfig = TracksConfig()) -> Tracks:
    path = Path(path)
    if tracks_format(path, fmt) == "json":
        return read_tracks_json(path)
    return read_kitti_labels(path, config.types)


# ---------------------------------------------------------------- into the package


def _frame_to_world(m, tracks: Tracks, camera: str | None, offset: np.ndarray | None):
    """Per package frame, the similarity [4, 4] from the tracks' frame to the world."""
    where = m.path or m.root
    if camera is not None and tracks.frame != "camera":
        raise InputError(tracks.path, f"the boxes are in the {tracks.frame} frame: --camera is for boxes in the "
                                      "camera frame", "frame")
    if tracks.frame == "world":
        return lambda fi: np.eye(4)
    if tracks.frame == "source":
        key = "poses_transform" if "poses_transform" in m.source else "transform"
        if key not in m.source:
            raise InputError(where, "no source transform (the package was not made by symdrive import): boxes in "
                                    "the source frame cannot be placed", "source.transform")
        T = np.asarray(m.source[key], dtype=np.float64)
        return lambda fi: T
    try:
        cam = m.camera(camera) if camera else m.cameras[0]
    except KeyError:
        raise InputError(where, f"no camera named {camera!r} (has: {', '.join(c.name for c in m.cameras)})",
                         "--camera") from None
    shift = np.eye(4)
    if offset is not None:
        shift[:3, 3] = -offset  # rectified cameras share their axes: x_cam2 = x_cam0 - offset
    return lambda fi: cam.frames[fi].camera_to_world @ shift


def _track_poses(track: Track, tracks: Tracks, to_world, nf: int, frame_offset: int):
    """(poses, world wlh, boxes outside the package's frames) of one track."""
    fields = _Fields(tracks.path)
    poses: list[Pose | None] = [None] * nf
    outside, wlh = 0, None
    for box in track.boxes:
        fi = box.frame - frame_offset
        if not 0 <= fi < nf:
            outside += 1
            continue
        s, R, t = decompose(to_world(fi))
        M = np.eye(4)
        M[:3, :3] = R @ box.rotation
        M[:3, 3] = _check_centre(fields, s * R @ box.centre + t, box.where)
        poses[fi] = Pose.from_matrix(M)
        wlh = s * track.wlh
    if wlh is not None:  # in metres now: a similarity scales the sizes
        for v, where in zip(wlh, track.size_where):
            _check_size(fields, v, where)
    return poses, wlh, outside


def _place(m, tracks: Tracks, new: list[tuple[Track, list, np.ndarray]], replace: bool) -> int:
    """Put the new actors in ``m.actors``: a replaced one keeps its place and instance id (masks and
    id maps name it), the others get ids after the largest. Returns how many were replaced."""
    by_id = {a.id: i for i, a in enumerate(m.actors)}
    for track in tracks.tracks:
        old = m.actors[by_id[track.id]] if track.id in by_id else None
        if old is not None and (old.kind != "existing" or not replace):
            hint = "; pass --replace to replace it" if old.kind == "existing" else ""
            raise InputError(tracks.path, f"actor {track.id!r} is already in the package (kind {old.kind}){hint}",
                             track.where)
    top = max((a.instance_id for a in m.actors), default=0)
    fresh = sum(track.id not in by_id for track, _, _ in new)
    if top + fresh > ID_MAX:
        raise InputError(tracks.path, f"{fresh} new actors after instance id {top} exceed the {ID_MAX} ids an id "
                                      "map holds", "tracks")
    replaced = 0
    for track, poses, wlh in new:
        if track.id in by_id:
            i = by_id[track.id]
            m.actors[i] = Actor(track.id, "existing", None, None, poses, wlh, m.actors[i].instance_id)
            replaced += 1
        else:
            top += 1
            m.actors.append(Actor(track.id, "existing", None, None, poses, wlh, top))
    return replaced


def import_tracks(package, tracks_file, *, fmt: str | None = None, camera: str | None = None,
                  calib=None, replace: bool = False, config: TracksConfig = TracksConfig()) -> dict:
    """Add the tracks in ``tracks_file`` to the package as ``existing`` actors (see
    :func:`add_tracks`). ``calib``: a KITTI calibration file whose ``P2`` moves boxes from camera
    0's frame into camera 2's. Returns a summary."""
    from ..scene import load_manifest

    m = load_manifest(package)
    tracks = read_tracks(tracks_file, fmt, config)
    offset = None if calib is None else read_camera_offset(calib)
    return add_tracks(m, tracks, camera=camera, offset=offset, replace=replace, frame_offset=config.frame_offset,
                      checks=config.checks)


def add_tracks(m, tracks: Tracks, *, camera: str | None = None, offset: np.ndarray | None = None,
               replace: bool = False, frame_offset: int = 0, checks: TrackChecks = TrackChecks()) -> dict:
    """Add ``tracks`` to the loaded package ``m`` as ``existing`` actors and save its manifest
    (atomically, after the whole result has been checked as a manifest). ``offset``: where the
    package camera sits in the frame of boxes given in camera coordinates (KITTI's camera 2 in
    camera 0's). ``replace``: tracks may replace actors of kind ``existing`` with the same id.
    Boxes that are no plausible motion are reported (:mod:`.track_checks`), in the summary and in
    ``source.tracks`` with the ids of the actors whose boxes came from tracks."""
    to_world = _frame_to_world(m, tracks, camera, offset)
    nf = len(m.frames)
    new, outside, empty = [], 0, 0
    for track in tracks.tracks:
        poses, wlh, out = _track_poses(track, tracks, to_world, nf, frame_offset)
        outside += out
        if wlh is None:
            empty += 1
        else:
            new.append((track, poses, wlh))
    replaced = _place(m, tracks, new, replace)
    reported = _record(m, [_check(m, track, poses, wlh, frame_offset, checks) for track, poses, wlh in new])
    parse_manifest(m.to_json(), m.path or m.root / "manifest.json")
    m.save()
    return {"package": str(m.root), "tracks": len(new), "replaced": replaced,
            "boxes": sum(p is not None for _, poses, _ in new for p in poses), "outside": outside,
            "tracks_outside": empty, "frames": nf, "skipped": tracks.skipped, "reported": reported}


def _check(m, track: Track, poses: list, wlh: np.ndarray, frame_offset: int, checks: TrackChecks) -> tuple:
    """(actor id, reports) of one imported track."""
    seen = [p is not None and in_view(m, p, wlh, f) for f, p in enumerate(poses)]
    sizes = {b.frame - frame_offset: b.wlh for b in track.boxes if b.wlh is not None}
    times = [f.timestamp for f in m.frames]
    return track.id, check_track(track.id, poses, times, seen, sizes, checks)


def _record(m, checked: list[tuple]) -> list[dict]:
    """Note in ``m.source["tracks"]`` which actors' boxes came from tracks (their poses are refined
    by the reconstruction by default) and what was reported about them, replacing an earlier
    import's notes of the same actors. Returns this import's reports."""
    ids = {actor for actor, _ in checked}
    notes = m.source.get("tracks", {})
    reports = [r.to_json() for _, found in checked for r in found]
    m.source["tracks"] = {"actors": sorted(set(notes.get("actors", [])) | ids),
                          "reported": [r for r in notes.get("reported", []) if r["actor"] not in ids] + reports}
    return reports
