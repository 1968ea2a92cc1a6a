"""Write the world's scene package: renders as jobs, then point cloud, assets and manifest.

Layout (paths relative to the package):

    manifest.json
    gt/train/000000.png          training drive (also the images of camera "front")
    gt/depth/000000.exr          OpenCV z-depth in metres, float; 0 where the ray meets the sky
    gt/lateral/+0.5/000000.png   the frame's camera moved 0.5 m to its right (lateral_shift)
    gt/lanes/recorded/000000.png lane-marking mask of a training-drive view (world.lanes, exact)
    gt/lanes/lateral/+0.5/000000.png  the same for a lateral view
    gt/insertion/00/with.png     vehicle placed in the scene (true light and shadow)
    gt/insertion/00/mask.png     its visible mask (object-index pass, exact)
    gt/insertion/00/shadow.png   its hard-shadow region (sunny scenes only)
    gt/vehicles/000000.png       the moving traffic's visible pixels in a drive frame (--traffic)
    gt/edits/00/image.png        a held-out frame with one traffic car removed, moved or retimed
                                 (--parked-existing: also one parked car removed per held-out frame)
    gt/edits/00/mask.png         that car's visible mask (edited render; for remove, the recorded one)
    background/points.ply        surface samples coloured from the training images
    assets/<kind>/{mesh.obj, mesh.mtl, splats.ply, wlh.json}
"""

from __future__ import annotations

import time
from pathlib import Path

import bpy
import numpy as np

from symdrive_core import conventions
from symdrive_core.insertion.surface import sample_surface
from symdrive_core.io.images import write_image, write_mask
from symdrive_core.io.points import write_points
from symdrive_core.scene import Actor, Camera, CameraFrame, Effects, Frame, Manifest, MaskEntry, Pose
from symdrive_core.world.projection import colour_points

from . import drive, lanes, render
from .assets import export_car
from .insertion import place_object, placement_pose, shadow_mask
from .meshdata import scene_triangles
from .parked import Parked
from .sensor import SensorEffects
from .street import LANE_WIDTH, LANES, build_street
from .traffic import EDIT_KINDS, RETIME_S, TRAFFIC_INDEX, Traffic, ego_vehicle
from .vehicles import ASSET_PAINTS, PRESETS, build_car

SPEED = 10.0  # m/s of the ego car: timestamps = distance / speed
INSERT_INDEX = 1  # object pass index of the inserted vehicle


def lateral_dir(offset: float) -> str:
    return f"{offset:+.1f}"


class PackageWriter:
    def __init__(self, root: Path, args):
        self.root, self.args = Path(root), args
        bpy.ops.wm.read_factory_settings(use_empty=True)
        drive_end = (args.frames - 1) * args.spacing
        self.street = build_street(args.seed, args.overcast, drive_end, args.material_jitter)
        render.setup_cycles(args.width, args.height, args.samples, args.seed)
        self.cam = render.make_camera(args.lens_mm)
        self.K = render.camera_K(self.cam)
        self.poses = drive.drive(self.street, args.frames, args.spacing, height=args.camera_height,
                                 pitch_deg=args.pitch)
        self.sensor = SensorEffects(args.noise, args.blur, args.exposure_jitter)
        self.heldout = list(range(args.holdout_every // 2, args.frames, args.holdout_every)) if args.holdout_every else []
        self.train = [i for i in range(args.frames) if i not in self.heldout]
        self.train_images: dict[int, np.ndarray] = {}
        self.train_depths: dict[int, np.ndarray] = {}
        self.lateral: dict[float, dict[str, str]] = {}
        self.lanes_recorded: dict[int, str] = {}
        self.lanes_lateral: dict[float, dict[int, str]] = {}
        self.insertions: list[dict] = []
        self.render_seconds: list[float] = []
        self.assets = self._make_assets()
        self.traffic = Traffic(self.street, args.traffic, args.seed, [self._time(i) for i in range(args.frames)],
                               ego_vehicle(SPEED)) if args.traffic else None
        self.vehicle_masks: dict[int, str] = {}
        self.vehicle_pixels: dict[int, np.ndarray] = {}  # frame -> visible pixels of each traffic car
        self.heldout_index: dict[int, np.ndarray] = {}  # held-out frame -> its object-index pass
        self.edits: list[dict] = []
        # --parked-existing: the parked cars in view, pass indices after the traffic's
        self.parked = Parked(self.street.parked, TRAFFIC_INDEX + args.traffic, self.poses, self.K, args.width,
                             args.height) if getattr(args, "parked_existing", False) else None
        self.parked_pixels: dict[int, np.ndarray] = {}  # held-out frame -> visible pixels of each parked car

    # ------------------------------------------------------------------ assets and renders
    def _make_assets(self) -> dict:
        col = bpy.data.collections.new("assets")
        bpy.context.scene.collection.children.link(col)
        out = {}
        for k, (kind, paint) in enumerate(sorted(ASSET_PAINTS.items())):
            obj = build_car(f"asset_{kind}", PRESETS[kind], paint, col)
            obj["kind"] = kind
            obj.pass_index = INSERT_INDEX
            obj.hide_render = True
            info = export_car(obj, self.root / "assets" / kind, self.args.asset_splats, self.args.seed + k)
            out[kind] = (obj, info)
        return out

    def _time(self, frame: int) -> float:
        return frame * self.args.spacing / SPEED

    def _render(self, c2w, frame: int, edited: dict | None = None):
        """Cycles render of ``c2w`` with the traffic as at ``frame`` (``edited``: see Traffic.show)."""
        if self.traffic is not None:
            self.traffic.show(frame, edited)
        t = time.perf_counter()
        out = render.render(self.cam, c2w)
        self.render_seconds.append(time.perf_counter() - t)
        return out

    def _record(self, rgb: np.ndarray, frame: int, rel: str) -> np.ndarray:
        """Write a render of ``frame`` at ``rel`` as the camera records it (:mod:`.sensor`)."""
        rgb = self.sensor.apply(rgb, self.args.seed, frame, rel)
        write_image(self.root / rel, rgb)
        return rgb

    def plan(self) -> list:
        """Every Cycles render as a job, training frames first (later jobs reuse their depth)."""
        jobs = [lambda i=i: self._train(i) for i in range(self.args.frames)]
        for off in self.args.offsets:
            jobs += [lambda i=i, off=off: self._lateral(i, off) for i in range(0, self.args.frames, self.args.lateral_every)]
        frames = self.heldout or list(range(self.args.frames))
        kinds = sorted(self.assets)
        jobs += [lambda k=k: self._insert(k, frames[k % len(frames)], kinds[k % len(kinds)])
                 for k in range(self.args.placements)]
        if self.traffic is not None:
            jobs += [lambda f=f, kind=kind: self._edit(f, kind) for f in self.heldout for kind in EDIT_KINDS]
        if self.parked is not None:
            jobs += [lambda f=f: self._parked_remove(f) for f in self.heldout]
        return jobs

    def _train(self, i: int) -> None:
        out = self._render(self.poses[i], i)
        rgb = self._record(out["rgb"], i, f"gt/train/{i:06d}.png")
        write_image(self.root / f"gt/depth/{i:06d}.exr", out["depth"], dtype="float")
        self.train_images[i], self.train_depths[i] = rgb, out["depth"]
        if self.traffic is not None:
            self._vehicle_mask(i, out["index"])
        if self.parked is not None and i in self.heldout:
            self.heldout_index[i] = out["index"]
            self.parked_pixels[i] = self.parked.pixels(out["index"])
        self.lanes_recorded[i] = self._lane_mask(self.poses[i], lanes.recorded_path(i))

    def _vehicle_mask(self, i: int, index: np.ndarray) -> None:
        """The traffic's visible pixels in drive frame ``i``, and each car's count (edits pick by it)."""
        rel = f"gt/vehicles/{i:06d}.png"
        write_mask(self.root / rel, (index >= TRAFFIC_INDEX) & (index < TRAFFIC_INDEX + len(self.traffic)))
        self.vehicle_masks[i] = rel
        self.vehicle_pixels[i] = np.bincount(index.ravel(), minlength=TRAFFIC_INDEX + len(self.traffic))[
            TRAFFIC_INDEX:TRAFFIC_INDEX + len(self.traffic)]
        if i in self.heldout:
            self.heldout_index[i] = index

    def _lane_mask(self, c2w, rel: str) -> str:
        write_mask(self.root / rel, lanes.lane_mask(self.cam, c2w))
        return rel

    def _lateral(self, i: int, offset: float) -> None:
        c2w = conventions.lateral_shift(self.poses[i], offset)
        out = self._render(c2w, i)
        rel = f"gt/lateral/{lateral_dir(offset)}/{i:06d}.png"
        self._record(out["rgb"], i, rel)
        self.lateral.setdefault(offset, {})[str(i)] = rel
        self.lanes_lateral.setdefault(offset, {})[i] = self._lane_mask(c2w, lanes.lateral_path(lateral_dir(offset), i))

    def _insert(self, k: int, frame: int, kind: str) -> None:
        obj, info = self.assets[kind]
        cam_x = self.poses[frame][0, 3]
        pose = placement_pose(self.street, cam_x, k, info["wlh"])
        place_object(obj, pose)
        obj.hide_render = False
        try:
            out = self._render(self.poses[frame], frame)
            mask = out["index"] == INSERT_INDEX
            shadow = None
            if self.street.sun_direction is not None:
                shadow = shadow_mask(obj, self.poses[frame], self.K, self.train_depths[frame], mask,
                                     self.street.sun_direction)
        finally:
            obj.hide_render = True
        base = f"gt/insertion/{k:02d}"
        self._record(out["rgb"], frame, f"{base}/with.png")
        write_mask(self.root / f"{base}/mask.png", mask)
        if shadow is not None:
            write_mask(self.root / f"{base}/shadow.png", shadow)
        self.insertions.append({
            "actor": f"insert_{k}", "asset": f"assets/{kind}", "kind": kind, "wlh": info["wlh"],
            "pose": pose.to_json(), "camera": "front", "frame": frame,
            "with": f"{base}/with.png", "without": f"gt/train/{frame:06d}.png",
            "mask": f"{base}/mask.png", "shadow_mask": None if shadow is None else f"{base}/shadow.png",
            "mask_pixels": int(mask.sum()), "shadow_pixels": 0 if shadow is None else int(shadow.sum()),
        })

    def _edit(self, frame: int, kind: str) -> None:
        """Held-out ``frame`` rendered again with its most visible traffic car (if it shows at least
        ``--edit-pixels``) removed, moved one lane across, or where it is RETIME_S later. An edit that
        would put the car on another or off the street is skipped."""
        pixels = self.vehicle_pixels[frame]
        k = int(np.argmax(pixels))
        if pixels[k] < self.args.edit_pixels:
            return
        extra = {}
        if kind == "remove":
            pose = None
        elif kind == "move":
            moved = self.traffic.moved(k, frame)
            if moved is None:
                return
            pose, extra["lateral_m"] = moved
        else:
            pose = self.traffic.retimed(k, frame, RETIME_S)
            if pose is None:
                return
            extra["shift_s"] = RETIME_S
        out = self._render(self.poses[frame], frame, {k: pose})
        mask = (self.heldout_index[frame] if pose is None else out["index"]) == TRAFFIC_INDEX + k
        base = f"gt/edits/{len(self.edits):02d}"
        self._record(out["rgb"], frame, f"{base}/image.png")
        write_mask(self.root / f"{base}/mask.png", mask)
        self.edits.append({"kind": kind, "actor": f"car_{k}", "camera": "front", "frame": frame,
                           "image": f"{base}/image.png", "mask": f"{base}/mask.png",
                           "pose": None if pose is None else pose.to_json(), **extra, "mask_pixels": int(mask.sum())})

    def _parked_remove(self, frame: int) -> None:
        """Held-out ``frame`` rendered again without its most visible parked car (at least
        ``--edit-pixels``) that no other edit of the frame is about; its mask is the car's visible
        pixels in the recorded frame."""
        used = {e["actor"] for e in self.edits if e["frame"] == frame}
        pixels = self.parked_pixels[frame]
        free = [k for k in range(len(self.parked))
                if self.parked.actor_id(k) not in used and pixels[k] >= self.args.edit_pixels]
        if not free:
            return
        k = max(free, key=lambda j: (pixels[j], -j))
        obj = self.parked.objects[k]
        obj.hide_render = True
        try:
            out = self._render(self.poses[frame], frame)
        finally:
            obj.hide_render = False
        mask = self.parked.mask(self.heldout_index[frame], k)
        base = f"gt/edits/{len(self.edits):02d}"
        self._record(out["rgb"], frame, f"{base}/image.png")
        write_mask(self.root / f"{base}/mask.png", mask)
        self.edits.append({"kind": "remove", "actor": self.parked.actor_id(k), "camera": "front", "frame": frame,
                           "image": f"{base}/image.png", "mask": f"{base}/mask.png", "pose": None,
                           "mask_pixels": int(mask.sum())})

    # ------------------------------------------------------------------ point cloud, manifest
    def _point_cloud(self) -> str:
        """Scene surfaces sampled (denser near the drive), kept where a training image sees them."""
        rng = np.random.default_rng(self.args.seed)
        verts, tris, _ = scene_triangles(self.street.background)
        centres = verts[tris].mean(1)
        path = np.array([p[:3, 3] for p in self.poses])
        d = np.min(np.linalg.norm(centres[:, None, :2] - path[None, ::3, :2], axis=2), axis=1)
        weights = 1.0 / (1.0 + (d / 15.0) ** 2)
        pts, normals, _ = sample_surface(verts, tris, 6 * self.args.points, rng, weights)
        views = [(self.K, conventions.invert_rigid(self.poses[i]), self.train_images[i], self.train_depths[i])
                 for i in self.train]
        colours, seen, _ = colour_points(pts, views)
        idx = np.nonzero(seen)[0]
        if len(idx) > self.args.points:
            idx = np.sort(rng.choice(idx, self.args.points, replace=False))
        write_points(self.root / "background/points.ply", pts[idx], colours[idx], normals[idx])
        self.n_points = len(idx)
        return "background/points.ply"

    def _manifest(self, points: str) -> Manifest:
        a = self.args
        nf = a.frames
        frames = [Frame(i, self._time(i)) for i in range(nf)]
        cam_frames = [CameraFrame(self.K, c2w, conventions.invert_rigid(c2w), f"gt/train/{i:06d}.png",
                                  f"gt/depth/{i:06d}.exr") for i, c2w in enumerate(self.poses)]
        actors, masks = [], []
        for k, ins in enumerate(self.insertions):
            poses = [None] * nf
            poses[ins["frame"]] = Pose(np.array(ins["pose"]["translation"]), np.array(ins["pose"]["rotation"]))
            actors.append(Actor(ins["actor"], "inserted", f"{ins['asset']}/splats.ply", f"{ins['asset']}/mesh.obj",
                                poses, np.array(ins["wlh"]), k + 1))
            masks.append(MaskEntry("front", ins["frame"], ins["actor"], visible=ins["mask"]))
        actors += self._traffic_actors(len(actors) + 1)
        actors += self._parked_actors(len(actors) + 1)
        sunny = self.street.sun_direction is not None
        ground_truth = {
            "camera": "front",
            "train_frames": self.train,
            "heldout_frames": self.heldout,
            "depth": "OpenCV z-depth in metres (float EXR); 0 where the ray meets the sky",
            "lateral": [{"offset_m": float(off), "camera": "front",
                         "frames": dict(sorted(self.lateral[off].items(), key=lambda kv: int(kv[0])))}
                        for off in sorted(self.lateral)],
            "insertion": self.insertions,
            "lanes": lanes.ground_truth_block("front", self.lanes_recorded, self.lanes_lateral),
            "road": {"centerline": np.round(self.street.centreline(), 4).tolist(), "lanes": LANES,
                     "lane_width": LANE_WIDTH},
            "generator": {
                "script": "scripts/make_world.py", "seed": a.seed, "width": a.width, "height": a.height,
                "frames": nf, "spacing_m": a.spacing, "samples": a.samples, "denoiser": "OpenImageDenoise",
                "overcast": a.overcast, "lateral_every": a.lateral_every, "blender": bpy.app.version_string,
                "seconds_per_render": round(self.seconds_per_render, 3), "renders": self.renders,
                "points": self.n_points, "colour": "sRGB (Standard view transform, no look)",
                "camera_height_m": a.camera_height, "pitch_deg": a.pitch, "lens_mm": a.lens_mm,
                "material_jitter": a.material_jitter, "sensor": self.sensor.to_json(),
            },
        }
        if self.traffic is not None:
            ground_truth["vehicles"] = {"camera": "front", "frames": {str(i): self.vehicle_masks[i]
                                                                      for i in sorted(self.vehicle_masks)}}
            ground_truth["edits"] = self.edits
            ground_truth["generator"].update(traffic=a.traffic, edit_pixels=a.edit_pixels)
        if self.parked is not None:
            ground_truth["edits"] = self.edits
            ground_truth["generator"].update(edit_pixels=a.edit_pixels, parked_existing=True)
        return Manifest(
            name=f"street-{a.seed}{'-overcast' if a.overcast else ''}", frames=frames,
            cameras=[Camera("front", a.width, a.height, cam_frames)], actors=actors,
            background_points=points, masks=masks,
            effects=Effects(lateral_offsets=[float(o) for o in a.offsets], harmonize=bool(self.insertions),
                            finetune=bool(self.insertions), shadows=sunny, sun_direction=self.street.sun_direction),
            ground_truth=ground_truth, root=self.root)

    def _traffic_actors(self, first_id: int) -> list[Actor]:
        """The traffic cars as recorded vehicles: exact per-frame poses and measured size; no
        assets (the reconstruction fits them in their boxes)."""
        if self.traffic is None:
            return []
        return [Actor(f"car_{k}", "existing", None, None, poses, np.array(self.traffic.wlh(k)), first_id + k)
                for k, poses in enumerate(self.traffic.poses)]

    def _parked_actors(self, first_id: int) -> list[Actor]:
        """The parked cars in view as existing actors: the same pose in every frame, measured size,
        no assets."""
        if self.parked is None:
            return []
        nf = self.args.frames
        return [Actor(self.parked.actor_id(k), "existing", None, None, [pose] * nf,
                      np.array(self.parked.sizes[k]), first_id + k) for k, pose in enumerate(self.parked.poses)]

    @property
    def renders(self) -> int:
        return len(self.render_seconds)

    @property
    def seconds_per_render(self) -> float:
        return float(np.mean(self.render_seconds)) if self.render_seconds else 0.0

    def finish(self) -> None:
        points = self._point_cloud()
        self._manifest(points).save(self.root / "manifest.json")
        if self.args.save_blend:
            bpy.ops.wm.save_as_mainfile(filepath=str(self.root / "world.blend"))
