"""A small street scene built through the add-on's operators: background splats, two cars, a camera."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from symdrive_core.io.ply import write_splats
from tests.addon.assets import write_car
from tests.conftest import random_gaussians

WIDTH, HEIGHT = 64, 48


def add_camera(bpy, name="front", lens=30.0, shift=(0.04, -0.03)):
    data = bpy.data.cameras.new(name)
    data.lens, data.sensor_fit = lens, "AUTO"
    data.shift_x, data.shift_y = shift
    cam = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(cam)
    cam.rotation_euler = (math.radians(88.0), 0.0, math.radians(-90.0))  # looking along +X, slightly down
    return cam


def two_car_scene(bpy, folder: Path, n_frames: int = 10):
    """Camera driving along +X; car A parked ahead, car B crossing in front of it along a curve."""
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = (
        WIDTH,
        HEIGHT,
        100,
    )
    scene.render.fps, scene.frame_start, scene.frame_end = 10, 1, n_frames
    bg_path = folder / "background.ply"
    write_splats(bg_path, random_gaussians(300, 0, 1, (20.0, 0.0, 1.0), 4.0))
    bpy.ops.symdrive.import_splats(filepath=str(bg_path))
    bg = bpy.context.active_object
    bg.location, bg.rotation_euler = (2.0, -1.0, 0.2), (0.0, 0.0, 0.3)  # a rigid, non-identity frame

    mesh_a, splat_a = write_car(folder / "car_a", "car_a", seed=1)
    scene.cursor.location = (13.0, 1.0, 0.0)
    bpy.ops.symdrive.import_vehicle(filepath=str(mesh_a), splat_filepath=str(splat_a))
    car_a = bpy.context.active_object
    car_a.rotation_euler.z = 0.4
    scene.frame_set(1)
    bpy.ops.symdrive.key_pose()
    scene.frame_set(n_frames)
    car_a.location.x += 1.0
    bpy.ops.symdrive.key_pose()

    mesh_b, splat_b = write_car(folder / "car_b", "car_b", seed=2)
    scene.cursor.location = (0.0, 0.0, 0.0)
    bpy.ops.symdrive.import_vehicle(filepath=str(mesh_b), splat_filepath=str(splat_b), flip_forward=True)
    car_b = bpy.context.active_object
    path = bpy.data.curves.new("crossing", "CURVE")
    path.dimensions = "3D"
    spline = path.splines.new("POLY")
    spline.points.add(1)
    spline.points[0].co, spline.points[1].co = (9.0, -6.0, 0.0, 1.0), (9.5, 6.0, 0.0, 1.0)
    curve = bpy.data.objects.new("crossing", path)
    scene.collection.objects.link(curve)
    scene.frame_set(1)
    bpy.ops.symdrive.follow_curve(curve="crossing", speed=12.0)

    cam = add_camera(bpy)
    for f in (1, n_frames):
        scene.frame_set(f)
        cam.location = (0.3 * (f - 1), 0.5, 1.6)
        cam.keyframe_insert("location", frame=f)
    scene.camera = cam
    scene.frame_set(1)
    return {"background": bg, "cars": [car_a, car_b], "camera": cam}


def rasterize_triangles(uv: np.ndarray, width: int, height: int) -> np.ndarray:
    """Pixels whose centre lies inside any projected triangle [T, 3, 2] (bool [H, W])."""
    out = np.zeros((height, width), dtype=bool)
    for tri in uv:
        lo = np.maximum(np.floor(tri.min(axis=0) - 0.5), 0).astype(int)
        hi = np.minimum(np.ceil(tri.max(axis=0) + 0.5), [width, height]).astype(int)
        if np.any(hi <= lo):
            continue
        u, v = np.meshgrid(np.arange(lo[0], hi[0]) + 0.5, np.arange(lo[1], hi[1]) + 0.5)
        p = np.stack([u, v], axis=-1)
        edges = []
        for i in range(3):
            a, b = tri[i], tri[(i + 1) % 3]
            edges.append((b[0] - a[0]) * (p[..., 1] - a[1]) - (b[1] - a[1]) * (p[..., 0] - a[0]))
        e = np.stack(edges)
        inside = np.all(e >= 0, axis=0) | np.all(e <= 0, axis=0)
        out[lo[1] : hi[1], lo[0] : hi[0]] |= inside
    return out


def iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.logical_or(a, b).sum()
    return 1.0 if union == 0 else float(np.logical_and(a, b).sum() / union)
