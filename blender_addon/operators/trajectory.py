"""Keyframing actors: by hand, along a curve at a speed, from a scene package, from SUMO FCD."""

from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np
from bpy.props import FloatProperty, FloatVectorProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from .. import actors, keyframes, path_sampling, reference_frame
from ..core import errors, fcd
from ..core import scene as scene_pkg


def _fps(scene) -> float:
    return scene.render.fps / scene.render.fps_base


def _yaw_matrices(positions, yaws) -> list[np.ndarray]:
    out = []
    for p, yaw in zip(positions, yaws, strict=True):
        M = np.eye(4)
        c, s = np.cos(yaw), np.sin(yaw)
        M[:2, :2] = [[c, -s], [s, c]]
        M[:3, 3] = p
        out.append(M)
    return out


CURVE_SURFACE = {"bevel_depth": 0.0, "extrude": 0.0, "bevel_object": None}  # what makes a curve a road's surface


def curve_polyline(curve: bpy.types.Object, depsgraph) -> path_sampling.Polyline:
    """The first spline of ``curve`` as evaluated (resolution, modifiers) in world coordinates:
    its centre line, with any bevel or extrusion (a curve drawn as a road) set aside meanwhile."""
    data = curve.data
    saved = {k: getattr(data, k) for k in CURVE_SURFACE}
    try:
        if any(saved[k] != v for k, v in CURVE_SURFACE.items()):
            for k, v in CURVE_SURFACE.items():
                setattr(data, k, v)
            depsgraph.update()
        evaluated = curve.evaluated_get(depsgraph)
        mesh = evaluated.to_mesh()
        try:
            co = np.empty(len(mesh.vertices) * 3)
            mesh.vertices.foreach_get("co", co)
            edges = np.empty(len(mesh.edges) * 2, dtype=np.int64)
            mesh.edges.foreach_get("vertices", edges)
        finally:
            evaluated.to_mesh_clear()
    finally:
        if any(getattr(data, k) != v for k, v in saved.items()):
            for k, v in saved.items():
                setattr(data, k, v)
            depsgraph.update()
    co, edges = co.reshape(-1, 3), edges.reshape(-1, 2)
    if len(co) < 2 or len(edges) == 0:
        raise errors.InputError(curve.name, "curve has no evaluated geometry (at least two points needed)")
    neighbours: dict[int, list[int]] = {}
    for a, b in edges.tolist():
        neighbours.setdefault(a, []).append(b)
        neighbours.setdefault(b, []).append(a)
    start = min(neighbours, key=lambda v: (len(neighbours[v]) != 1, v))  # an open end if there is one
    order, previous, current, cyclic = [start], None, start, False
    while True:
        ahead = sorted(v for v in neighbours[current] if v != previous)
        if not ahead:
            break
        if ahead[0] == start and previous is not None:
            cyclic = True
            break
        order.append(ahead[0])
        previous, current = current, ahead[0]
    M = np.array(curve.matrix_world)
    pts = co[order] @ M[:3, :3].T + M[:3, 3]
    return path_sampling.Polyline(pts, cyclic=cyclic)


def _active_actor(context, op) -> bpy.types.Object | None:
    root = actors.actor_of(context.active_object)
    if root is None:
        op.report({"ERROR"}, "select a vehicle (an actor imported with Import Vehicle)")
    return root


class SYMDRIVE_OT_key_pose(bpy.types.Operator):
    """Keyframe the location and heading of the selected vehicles at the current frame"""

    bl_idname = "symdrive.key_pose"
    bl_label = "Key Vehicle Pose"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        roots = actors.selected_actors(context, self)
        if not roots:
            return {"CANCELLED"}
        frame = context.scene.frame_current
        for root in roots:
            root.keyframe_insert("location", frame=frame)
            rotation = {"QUATERNION": "rotation_quaternion", "AXIS_ANGLE": "rotation_axis_angle"}.get(
                root.rotation_mode, "rotation_euler"
            )
            root.keyframe_insert(rotation, frame=frame)
        self.report({"INFO"}, f"Keyed {len(roots)} vehicle(s) at frame {frame}")
        return {"FINISHED"}


class SYMDRIVE_OT_follow_curve(bpy.types.Operator):
    """Keyframe the active vehicle driving along a curve at a constant speed, heading along the tangent"""

    bl_idname = "symdrive.follow_curve"
    bl_label = "Drive Along Curve"
    bl_options = {"REGISTER", "UNDO"}

    curve: StringProperty(
        name="Curve", default="", description="Curve object (default: the panel's path curve)"
    )
    speed: FloatProperty(name="Speed (m/s)", default=-1.0, description="Negative: the panel's speed")
    frame_start: IntProperty(name="Start frame", default=-1, description="Negative: the current frame")
    frame_end: IntProperty(name="End frame", default=-1, description="Negative: the scene's end frame")
    start_distance: FloatProperty(
        name="Start distance",
        default=0.0,
        unit="LENGTH",
        description="Where along the curve the vehicle is at the start frame",
    )

    def execute(self, context):
        scene = context.scene
        root = _active_actor(context, self)
        if root is None:
            return {"CANCELLED"}
        curve = bpy.data.objects.get(self.curve) if self.curve else scene.symdrive.curve
        if curve is None or curve.type != "CURVE":
            self.report({"ERROR"}, f"no curve object {self.curve!r}" if self.curve else "choose a path curve")
            return {"CANCELLED"}
        speed = scene.symdrive.speed if self.speed < 0 else self.speed
        f0 = scene.frame_current if self.frame_start < 0 else self.frame_start
        f1 = scene.frame_end if self.frame_end < 0 else self.frame_end
        if f1 < f0:
            self.report({"ERROR"}, f"end frame {f1} is before start frame {f0}")
            return {"CANCELLED"}
        try:
            path = curve_polyline(curve, context.evaluated_depsgraph_get())
        except (errors.SymDriveError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        frame_numbers = np.arange(f0, f1 + 1)
        distance = self.start_distance + speed * (frame_numbers - f0) / _fps(scene)
        if not path.cyclic:
            on_path = distance <= path.length + 1e-6
            frame_numbers, distance = frame_numbers[on_path], distance[on_path]
        pos, tangent = path.sample(distance)
        pos[:, 2] += root.symdrive.ground_offset
        keyframes.key_world_poses(root, frame_numbers, _yaw_matrices(pos, path_sampling.heading(tangent)))
        end = "" if len(frame_numbers) == f1 - f0 + 1 else f" (end of the curve at frame {frame_numbers[-1]})"
        self.report({"INFO"}, f"Keyed {len(frame_numbers)} frames along {curve.name!r} at {speed:g} m/s{end}")
        return {"FINISHED"}


class SYMDRIVE_OT_import_package_poses(bpy.types.Operator, ImportHelper):
    """Keyframe vehicles with the per-frame poses of a scene package (matched by actor id)"""

    bl_idname = "symdrive.import_package_poses"
    bl_label = "Poses from Scene Package"
    bl_options = {"REGISTER", "UNDO"}

    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={"HIDDEN"})

    def execute(self, context):
        scene = context.scene
        try:
            manifest = scene_pkg.load_manifest(self.filepath)
            bg = reference_frame.background_matrix(scene)
        except errors.SymDriveError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        by_id = {root.symdrive.actor_id: root for root in actors.all_actors(scene)}
        matched = [a for a in manifest.actors if a.id in by_id]
        if not matched:
            self.report(
                {"ERROR"},
                f"no vehicle in this scene has one of the package's actor ids: "
                f"{', '.join(a.id for a in manifest.actors) or '(none)'}",
            )
            return {"CANCELLED"}
        for actor in matched:
            root = by_id[actor.id]
            flip_inv = np.array(actors.asset_frame(root).inverted())
            present = [p is not None for p in actor.poses]
            keyed = [
                (scene.frame_start + i, np.array(bg) @ p.matrix() @ flip_inv)
                for i, p in enumerate(actor.poses)
                if p is not None
            ]
            if keyed:
                keyframes.key_world_poses(root, [f for f, _ in keyed], [M for _, M in keyed])
            keyframes.key_presence(root, range(scene.frame_start, scene.frame_start + len(present)), present)
        self.report({"INFO"}, f"Keyed {len(matched)} vehicle(s) over {len(manifest.frames)} frames")
        return {"FINISHED"}


class SYMDRIVE_OT_import_sumo_fcd(bpy.types.Operator, ImportHelper):
    """Keyframe vehicles from a SUMO FCD file (positions in the background's frame)"""

    bl_idname = "symdrive.import_sumo_fcd"
    bl_label = "Trajectories from SUMO FCD"
    bl_options = {"REGISTER", "UNDO"}

    filename_ext = ".xml"
    filter_glob: StringProperty(default="*.xml", options={"HIDDEN"})
    vehicle_id: StringProperty(
        name="SUMO vehicle",
        default="",
        description="Drive the active vehicle with this SUMO id; empty: match actor ids",
    )
    time_offset: FloatProperty(name="Time at start frame (s)", default=0.0)
    offset: FloatVectorProperty(
        name="Offset",
        size=3,
        unit="LENGTH",
        description="Added to SUMO positions (e.g. minus the network offset)",
    )

    def execute(self, context):
        scene = context.scene
        try:
            tracks = fcd.read_fcd(self.filepath)
            bg = np.array(reference_frame.background_matrix(scene))
        except errors.SymDriveError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        if self.vehicle_id:
            root = _active_actor(context, self)
            if root is None:
                return {"CANCELLED"}
            if self.vehicle_id not in tracks:
                self.report({"ERROR"}, f"{self.filepath}: no vehicle {self.vehicle_id!r} in the FCD file")
                return {"CANCELLED"}
            pairs = [(root, tracks[self.vehicle_id])]
        else:
            pairs = [
                (r, tracks[r.symdrive.actor_id])
                for r in actors.all_actors(scene)
                if r.symdrive.actor_id in tracks
            ]
            if not pairs:
                known = ", ".join(sorted(tracks)[:8]) or "(none)"
                self.report({"ERROR"}, f"no actor id matches a SUMO vehicle id (file has: {known})")
                return {"CANCELLED"}
        frame_numbers = np.arange(scene.frame_start, scene.frame_end + 1)
        times = self.time_offset + (frame_numbers - scene.frame_start) / _fps(scene)
        for root, track in pairs:
            pos, yaw, inside = fcd.sample_track(track, times, length=root.symdrive.wlh[1])
            pos = pos + np.array(self.offset) + np.array([0.0, 0.0, root.symdrive.ground_offset])
            world = [bg @ M for M in _yaw_matrices(pos[inside], yaw[inside])]
            if world:
                keyframes.key_world_poses(root, frame_numbers[inside], world)
            keyframes.key_presence(root, frame_numbers, inside)
        self.report({"INFO"}, f"Keyed {len(pairs)} vehicle(s) from {Path(self.filepath).name}")
        return {"FINISHED"}
