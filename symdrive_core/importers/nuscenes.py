"""A nuScenes scene -> :class:`~.package.Source` of its cameras, with its LiDAR and annotated vehicles.

nuScenes ships ``DATAROOT/VERSION/*.json`` tables (:mod:`.nuscenes_tables`) beside the recorded
files they name (``samples/CAM_FRONT/*.jpg``, ``samples/LIDAR_TOP/*.pcd.bin``). A scene is a list
of keyframe ``sample`` records linked by ``next``; each sensor's keyframe of a sample is the
``sample_data`` with that ``sample_token`` and ``is_key_frame`` (its channel is its
``calibrated_sensor``'s ``sensor``'s). The package's frames are the scene's samples (named by
their tokens, 2 Hz), its cameras the channels chosen (six by default), each camera's image of a
frame its keyframe of that sample.

The cameras of one sample do not fire at once (they expose as the LiDAR sweeps past them, tens of
milliseconds apart), and nuScenes records an ``ego_pose`` per ``sample_data`` at that record's own
timestamp. So every pose is composed at its own time: a camera's pose for an image is the
vehicle's pose when the image was taken (its ``ego_pose``, the vehicle in the global frame) times
the camera's place on the vehicle (its ``calibrated_sensor``, OpenCV axes as the package's); the
LiDAR's pose for a sweep likewise; and a sweep reaches a camera's image through both, global frame
in between, as the devkit's ``map_pointcloud_to_image`` does. The global frame is metric with Z
up: the source frame, at scale 1. ``camera_intrinsic`` puts pixel centres at integer coordinates;
the package's K puts them at +0.5.

The LiDAR enters two ways, from the keyframe sweeps: each camera's sparse depth (the sweep moved
into the camera at the image's time and projected by :func:`.lidar.write_depth`), and the returns
the first camera sees, coloured from its images (:func:`.lidar.seen_returns`), as the source's
points: a metric ground under the path and the reconstruction's start. Annotated instances of the
chosen categories (``sample_annotation`` by ``instance_token``; boxes in the global frame, centred,
``size`` = w, l, h, axes x forward, y left, z up as the 3DRealCar frame) become ``existing``
actors through the tracks writer (:func:`.tracks.add_tracks`). Depth and actors are added inside
the package's temporary folder, so a scene comes in whole or not at all; every table, image and
sweep is read and checked before anything is written.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import conventions
from ..errors import InputError
from ..scene.manifest import WLH_MAX
from .frames import View, group_views, in_order
from .lidar import LidarConfig, seen_returns
from .nuscenes_tables import Table, Tables
from .package import Source, check_image
from .tracks import Box, Track, Tracks

# nuScenes' six cameras, clockwise from the front (the devkit's order).
CAMERAS = ("CAM_FRONT", "CAM_FRONT_RIGHT", "CAM_BACK_RIGHT", "CAM_BACK", "CAM_BACK_LEFT", "CAM_FRONT_LEFT")
LIDAR = "LIDAR_TOP"
US = 1e-6  # nuScenes timestamps are microseconds


@dataclass(frozen=True)
class NuScenesConfig:
    # The tables' folder under DATAROOT.
    version: str = "v1.0-mini"
    # Channels made package cameras, in this order; the first is the package's first camera
    # (ground truth, the returns that colour the source's points).
    cameras: tuple[str, ...] = CAMERAS
    # Annotated categories imported as vehicles: a name or the prefix of names (vehicle.car, ...).
    categories: tuple[str, ...] = ("vehicle",)
    # LiDAR returns seen by the first camera kept as the source's points (spread over the sweeps).
    lidar_points: int = 100_000
    lidar: LidarConfig = field(default_factory=LidarConfig)


@dataclass
class NuScenesScene:
    """What was read: the source, and what :meth:`extend` adds to the written package."""

    source: Source
    scans: list[Path] | None  # the keyframe sweeps, in frame order (None: the scene has no LIDAR_TOP)
    sensor_to_camera: dict[str, list[np.ndarray]]  # camera -> per frame, the sweep into its image
    tracks: Tracks
    config: NuScenesConfig
    progress: bool = True

    def extend(self, folder: Path) -> dict:
        """Each camera's sparse depth and the annotated vehicles as actors, in the package being
        written at ``folder``; a summary for the command's report."""
        from ..scene import load_manifest
        from .lidar import write_depth
        from .tracks import add_tracks

        m = load_manifest(folder)
        lidar = []
        if self.scans is not None:
            for cam in m.cameras:
                lidar.append(write_depth(m, cam, self.scans, self.sensor_to_camera[cam.name],
                                         config=self.config.lidar, progress=self.progress))
        return {"lidar": lidar, "tracks": add_tracks(m, self.tracks)}


def _scene(tables: Tables, name: str) -> tuple[str, Table]:
    scenes = tables["scene"]
    names = {scenes.text(t, "name"): t for t in scenes.records}
    if name not in names:
        raise InputError(scenes.path, f"no scene {name!r}; the scenes: {', '.join(sorted(names)) or 'none'}",
                         "--scene")
    return names[name], scenes


def _samples(tables: Tables, scene: str, scenes: Table) -> list[str]:
    """The scene's sample tokens from ``first_sample_token`` along ``next``."""
    samples = tables["sample"]
    token, _ = tables.follow(scenes, scene, "first_sample_token", "sample")
    out: list[str] = []
    while True:
        if samples.text(token, "scene_token") != scene:
            samples.fail(token, "scene_token", f"the sample is linked into scene {scene!r} but names another")
        out.append(token)
        if samples.text(token, "next") == "":
            return out
        if len(out) == len(samples.records):
            samples.fail(token, "next", "the samples' next links form a loop")
        token, _ = tables.follow(samples, token, "next", "sample")


def _keyframes(tables: Tables, samples: list[str]) -> dict[str, dict[str, str]]:
    """sample token -> channel -> its keyframe's sample_data token."""
    sd = tables["sample_data"]
    out: dict[str, dict[str, str]] = {s: {} for s in samples}
    for token in sd.records:
        sample = sd.text(token, "sample_token")
        if sample not in out or not sd.flag(token, "is_key_frame"):
            continue
        cs_token, _ = tables.follow(sd, token, "calibrated_sensor_token", "calibrated_sensor")
        sensor, _ = tables.follow(tables["calibrated_sensor"], cs_token, "sensor_token", "sensor")
        channel = tables["sensor"].text(sensor, "channel")
        if channel in out[sample]:
            sd.fail(token, "is_key_frame", f"sample {sample!r} has a keyframe of {channel} already "
                                           f"({out[sample][channel]!r})")
        out[sample][channel] = token
    return out


def _keyframe(sd: Table, keyframes: dict[str, dict[str, str]], sample: str, channel: str, flag: str) -> str:
    if channel not in keyframes[sample]:
        has = ", ".join(sorted(keyframes[sample])) or "none"
        raise InputError(sd.path, f"sample {sample!r} has no keyframe of {channel} (has: {has})", flag)
    return keyframes[sample][channel]


def _world_from_sensor(tables: Tables, token: str) -> np.ndarray:
    """A sample_data's sensor in the global frame at the record's own time: its ego pose times
    its calibrated sensor."""
    sd = tables["sample_data"]
    ego, _ = tables.follow(sd, token, "ego_pose_token", "ego_pose")
    cs, _ = tables.follow(sd, token, "calibrated_sensor_token", "calibrated_sensor")
    return tables["ego_pose"].rigid(ego) @ tables["calibrated_sensor"].rigid(cs)


def _intrinsics(tables: Tables, token: str) -> np.ndarray:
    """A camera's package K from its ``camera_intrinsic`` (pixel centres moved to +0.5)."""
    cs = tables["calibrated_sensor"]
    K = cs.numbers(token, "camera_intrinsic", (3, 3), "a 3x3 matrix (a list of 3 rows of 3 numbers)")
    if not (K[0, 0] > 0 and K[1, 1] > 0 and K[0, 1] == 0 and K[1, 0] == 0 and np.array_equal(K[2], [0, 0, 1])):
        cs.fail(token, "camera_intrinsic", "not a pinhole K [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0")
    return conventions.intrinsics(K[0, 0], K[1, 1], K[0, 2] + conventions.PIXEL_CENTER_OFFSET,
                                  K[1, 2] + conventions.PIXEL_CENTER_OFFSET)


def _camera_view(tables: Tables, dataroot: Path, token: str, channel: str, sample: str, several: bool,
                 t0: int) -> View:
    sd = tables["sample_data"]
    cs, _ = tables.follow(sd, token, "calibrated_sensor_token", "calibrated_sensor")
    sensor, _ = tables.follow(tables["calibrated_sensor"], cs, "sensor_token", "sensor")
    modality = tables["sensor"].text(sensor, "modality")
    if modality != "camera":
        raise InputError(tables["sensor"].path, f"{channel} is a {modality}, not a camera", "--cameras")
    # {channel}/{sample} for several cameras, the sample alone for one: the package's frame names
    # are the sample tokens either way (what annotations are placed by).
    return View(name=f"{channel}/{sample}" if several else sample, K=_intrinsics(tables, cs),
                width=sd.integer(token, "width", 1), height=sd.integer(token, "height", 1),
                c2w=_world_from_sensor(tables, token), source=sd.path, where=f"[{token}]",
                image=sd.file(token, "filename", dataroot), timestamp=(sd.integer(token, "timestamp") - t0) * US)


def _category(tables: Tables, annotation: str) -> tuple[str, str]:
    """(instance token, category name) of a sample_annotation."""
    instance, _ = tables.follow(tables["sample_annotation"], annotation, "instance_token", "instance")
    category, _ = tables.follow(tables["instance"], instance, "category_token", "category")
    return instance, tables["category"].text(category, "name")


def _tracks(tables: Tables, frames: dict[str, int], categories: tuple[str, ...]) -> tuple[Tracks, dict[str, str]]:
    """(the annotated instances of ``categories`` as tracks in the global frame, actor id ->
    instance token). An actor is named after its category's last word and its place among the
    scene's vehicles in order of first appearance (``car_0``)."""
    ann = tables["sample_annotation"]
    boxes: dict[str, list[tuple[str, Box, np.ndarray]]] = {}
    kinds: dict[str, str] = {}
    skipped: dict[str, int] = {}
    for token in ann.records:
        sample, _ = tables.follow(ann, token, "sample_token", "sample")  # of this scene or another
        if sample not in frames:
            continue
        instance, name = _category(tables, token)
        if not any(name == c or name.startswith(c + ".") for c in categories):
            skipped[name] = skipped.get(name, 0) + 1
            continue
        wlh = ann.numbers(token, "size", (3,), "3 numbers (w, l, h in metres)")
        if not ((wlh > 0) & (wlh <= WLH_MAX)).all():
            ann.fail(token, "size", f"w, l, h must lie in (0, {WLH_MAX:g}] metres, got {', '.join(f'{x:g}' for x in wlh)}")
        centre = ann.numbers(token, "translation", (3,), "3 numbers (x, y, z in metres)")
        box = Box(frames[sample], centre, ann.rotation(token), f"[{token}]")
        boxes.setdefault(instance, []).append((token, box, wlh))
        kinds[instance] = name.rsplit(".", 1)[-1]
    for rows in boxes.values():
        rows.sort(key=lambda r: r[1].frame)
    tracks, instances = [], {}
    for i, (instance, rows) in enumerate(sorted(boxes.items(), key=lambda item: item[1][0][1].frame)):
        first = rows[0][0]
        actor = f"{kinds[instance]}_{i}"
        instances[actor] = instance
        tracks.append(Track(actor, np.median(np.stack([r[2] for r in rows]), axis=0), [r[1] for r in rows],
                            f"[{first}].instance_token", (f"[{first}].size",) * 3))
    return Tracks(ann.path, "source", tracks, skipped), instances


def read_nuscenes(dataroot: str | Path, scene: str, config: NuScenesConfig = NuScenesConfig(), *, splats=None,
                  progress: bool = True) -> NuScenesScene:
    """Read and check scene ``scene`` of the tables ``DATAROOT/config.version``: its keyframe
    images of ``config.cameras``, their poses, the LIDAR_TOP sweeps and the annotated vehicles.
    A splat PLY (``splats``) is taken to be in the source frame: nuScenes' global frame."""
    dataroot = Path(dataroot)
    if not dataroot.is_dir():
        raise InputError(dataroot, "not a folder (expected nuScenes' DATAROOT: VERSION/ tables, samples/)",
                         "DATAROOT")
    tables = Tables(dataroot / config.version)
    scene_token, scenes = _scene(tables, scene)
    samples = _samples(tables, scene_token, scenes)
    keyframes = _keyframes(tables, samples)
    sd = tables["sample_data"]
    t0 = tables["sample"].integer(samples[0], "timestamp")
    several = len(config.cameras) > 1
    views = [_camera_view(tables, dataroot, _keyframe(sd, keyframes, s, channel, "--cameras"), channel, s,
                          several, t0)
             for channel in config.cameras for s in samples]
    grouped = in_order(group_views(views, camera_name=config.cameras[0]), tuple(config.cameras))
    frames = {name: fi for fi, name in enumerate(grouped.frame_keys)}
    scans, points, colors, point_frames, to_camera = None, None, None, None, {}
    if any(LIDAR in keyframes[s] for s in samples):
        sweeps = [_keyframe(sd, keyframes, s, LIDAR, LIDAR) for s in grouped.frame_keys]
        scans = [sd.file(t, "filename", dataroot) for t in sweeps]
        world_from_lidar = [_world_from_sensor(tables, t) for t in sweeps]
        for cam, row in zip(grouped.cameras, grouped.table):
            to_camera[cam] = [conventions.invert_rigid(v.c2w) @ w for v, w in zip(row, world_from_lidar)]
        first = grouped.table[0]
        for v in first:  # read for their colours before the package checks them
            check_image(v.image, v.width, v.height, v.source, v.where)
        points, colors, point_frames = seen_returns(
            scans, world_from_lidar, to_camera[grouped.cameras[0]], first[0].K, first[0].width,
            first[0].height, [v.image for v in first], config.lidar_points, config.lidar.min_depth_m)
    tracks, instances = _tracks(tables, frames, tuple(config.categories))
    log, _ = tables.follow(scenes, scene_token, "log_token", "log")
    g = None
    if splats is not None:
        from ..io.ply import read_splats

        g = read_splats(splats)
    notes = {"nuscenes": {"version": config.version, "scene": scene, "scene_token": scene_token,
                          "location": tables["log"].text(log, "location"), "time_origin_us": t0,
                          "instances": instances}}
    src = Source("nuscenes", dataroot, grouped, splats=g, splats_path=None if splats is None else Path(splats),
                 points=points, colors=colors, point_frames=point_frames, notes=notes)
    return NuScenesScene(src, scans, to_camera, tracks, config, progress)
