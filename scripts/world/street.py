"""The procedural street: road, markings, kerbs, sidewalks, facades, trees, lamps, signs,
parked cars, sky and sun. Deterministic for a given seed.

The road runs along +X, gently curving: its centreline is ``y = amp * sin(2 pi x / period)``.
Cross-section (metres from the centreline, positive to the left): two 3.5 m lanes (right-hand
traffic), a 2.2 m parking strip each side, a 0.15 m kerb, a 3 m sidewalk, then buildings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import bmesh
import bpy
import numpy as np
from mathutils import Vector

from . import materials
from .geometry import box, cylinder, place, strip
from .vehicles import PRESETS, build_car

LANE_WIDTH = 3.5
LANES = 2
ROAD_HALF = LANE_WIDTH * LANES / 2 + 2.2  # lanes + parking strip
KERB_H = 0.15
SIDEWALK = 3.0
X_START, X_END = -30.0, 230.0
MARKING = "lane_marking"  # custom property set on every lane-marking object (gt/lanes masks)
PARK_OFFSET = LANE_WIDTH + 1.1  # parked cars' centre, from the centreline
PAINTS = [(0.6, 0.05, 0.04), (0.05, 0.12, 0.4), (0.75, 0.75, 0.73), (0.03, 0.03, 0.035),
          (0.35, 0.36, 0.38), (0.1, 0.3, 0.12), (0.7, 0.45, 0.08), (0.5, 0.52, 0.55)]


@dataclass
class Street:
    amp: float
    period: float
    background: list = field(default_factory=list)  # objects of the static scene
    parked: list = field(default_factory=list)  # the parked cars (also in ``background``), in build order
    sun_direction: np.ndarray | None = None  # direction the light travels, world, unit

    def centre_y(self, x):
        return self.amp * np.sin(2 * np.pi * np.asarray(x) / self.period)

    def heading(self, x):
        dy = self.amp * 2 * np.pi / self.period * np.cos(2 * np.pi * np.asarray(x) / self.period)
        return np.arctan2(dy, 1.0)

    def frame_at(self, x, lateral):
        """Point on the ground at ``lateral`` metres left of the centreline at ``x``, and heading."""
        yaw = float(self.heading(x))
        n = np.array([-math.sin(yaw), math.cos(yaw)])
        p = np.array([float(x), float(self.centre_y(x))]) + lateral * n
        return p, yaw

    def centreline(self, step=2.0):
        xs = np.arange(X_START, X_END + 1e-9, step)
        return np.stack([xs, self.centre_y(xs), np.zeros_like(xs)], 1)


def _path(street: Street, x0=X_START, x1=X_END, step=1.0):
    xs = np.arange(x0, x1 + 1e-9, step)
    yaw = street.heading(xs)
    path = np.stack([xs, street.centre_y(xs)], 1)
    normals = np.stack([-np.sin(yaw), np.cos(yaw)], 1)
    return path, normals


GROUND = ("asphalt", "paint", "kerb", "sidewalk", "verge")  # the materials material_jitter tints


def _road(street: Street, col, tints: dict[str, np.ndarray]):
    def c(name, rgb):
        return tuple(float(v) for v in np.clip(np.asarray(rgb) * tints[name], 0.0, 1.0))

    mats = {
        "asphalt": materials.mottled("asphalt", c("asphalt", (0.05, 0.05, 0.055)), c("asphalt", (0.13, 0.13, 0.13)),
                                     4.0, 0.85),
        "paint": materials.plain("marking", c("paint", (0.85, 0.85, 0.82)), 0.5),
        "kerb": materials.mottled("kerb", c("kerb", (0.42, 0.41, 0.4)), c("kerb", (0.58, 0.57, 0.55)), 6.0, 0.8, 0.05),
        "sidewalk": materials.tiles("sidewalk", c("sidewalk", (0.5, 0.48, 0.45)), c("sidewalk", (0.22, 0.21, 0.2)), 0.6),
        "verge": materials.mottled("verge", c("verge", (0.12, 0.16, 0.06)), c("verge", (0.25, 0.27, 0.12)), 1.5, 0.9),
    }
    path, normals = _path(street)
    objs = [strip("road", path, normals, [-ROAD_HALF, 0.0, ROAD_HALF], [0, 0, 0], mats["asphalt"], col)]
    for side in (-1, 1):
        edge = side * LANE_WIDTH * LANES / 2
        line = strip(f"edge_line_{side}", path, normals, [edge - 0.08, edge + 0.08], [0.004, 0.004],
                     mats["paint"], col)
        line[MARKING] = True
        objs.append(line)
        k0, k1 = side * ROAD_HALF, side * (ROAD_HALF + 0.15)
        lateral, heights = ([k0, k0, k1], [0.0, KERB_H, KERB_H]) if side > 0 else ([k1, k0, k0], [KERB_H, KERB_H, 0.0])
        objs.append(strip(f"kerb_{side}", path, normals, lateral, heights, mats["kerb"], col))
        s0, s1 = sorted([k1, side * (ROAD_HALF + 0.15 + SIDEWALK)])
        objs.append(strip(f"sidewalk_{side}", path, normals, [s0, s1], [KERB_H, KERB_H], mats["sidewalk"], col))
        v0, v1 = sorted([side * (ROAD_HALF + 0.15 + SIDEWALK), side * 40.0])
        objs.append(strip(f"verge_{side}", path[::4], normals[::4], [v0, v1], [KERB_H, KERB_H], mats["verge"], col))
    for x0 in np.arange(X_START, X_END - 3.0, 8.0):  # dashed centre line: 3 m on, 5 m off
        p, n = _path(street, x0, x0 + 3.0, 0.5)
        dash = strip(f"dash_{int(x0 - X_START)}", p, n, [-0.07, 0.07], [0.004, 0.004], mats["paint"], col)
        dash[MARKING] = True
        objs.append(dash)
    return objs


def _facades(rng):
    out = []
    for i in range(8):
        base = np.array(rng.choice([(0.75, 0.68, 0.55), (0.62, 0.35, 0.25), (0.8, 0.8, 0.76),
                                    (0.55, 0.6, 0.65), (0.7, 0.55, 0.4), (0.45, 0.42, 0.4)]))
        base = np.clip(base * rng.uniform(0.85, 1.1, 3), 0, 1)
        brick = bool(i % 3 == 1)
        out.append(materials.facade(f"facade_{i}", tuple(base), tuple(base * 0.8), (0.08, 0.1, 0.13),
                                    storey=rng.uniform(2.9, 3.6), bay=rng.uniform(2.2, 3.4),
                                    window_frac=rng.uniform(0.35, 0.55), brick=brick))
    return out


def _buildings(street: Street, rng, col):
    facades = _facades(rng)
    roof = materials.plain("roof", (0.2, 0.2, 0.21), 0.9)
    objs = []
    for side in (-1, 1):
        x = X_START + rng.uniform(0, 4)
        i = 0
        while x < X_END - 5:
            w, d, h = rng.uniform(8, 16), rng.uniform(8, 14), rng.uniform(7, 22)
            setback = rng.uniform(0.0, 1.5) if rng.random() < 0.6 else 0.0
            (cx, cy), yaw = street.frame_at(x + w / 2, side * (ROAD_HALF + 0.15 + SIDEWALK + setback + d / 2))
            obj = box(f"building_{side}_{i}", (w, d, h), (cx, cy, KERB_H), yaw, facades[rng.integers(len(facades))], col)
            obj.data.materials.append(roof)
            obj.data.polygons[1].material_index = 1  # the top face
            objs.append(obj)
            x += w + (rng.uniform(0.5, 3.0) if rng.random() < 0.5 else 0.0)
            i += 1
    (cx, cy), yaw = street.frame_at(X_END + 3, 0.0)
    objs.append(box("end_building", (6, 60, 18), (cx, cy, 0.0), yaw, facades[0], col))
    return objs


def _tree(name, location, rng, trunk_mat, leaf_mat, col):
    trunk = cylinder(f"{name}_trunk", 0.13, 2.6, location, trunk_mat, 8, col)
    bm = bmesh.new()
    radius = rng.uniform(1.3, 1.9)
    bmesh.ops.create_icosphere(bm, subdivisions=2, radius=radius)
    for v in bm.verts:
        v.co *= 1.0 + 0.18 * rng.standard_normal()
    mesh = bpy.data.meshes.new(f"{name}_crown")
    bm.to_mesh(mesh)
    bm.free()
    mesh.materials.append(leaf_mat)
    crown = bpy.data.objects.new(mesh.name, mesh)
    col.objects.link(crown)
    place(crown, (location[0], location[1], location[2] + 2.4 + radius * 0.8))
    return [trunk, crown]


def _props(street: Street, rng, col):
    metal = materials.plain("pole_metal", (0.3, 0.31, 0.32), 0.4, 0.6)
    bark = materials.mottled("bark", (0.12, 0.08, 0.05), (0.22, 0.15, 0.09), 10.0, 0.9)
    leaves = materials.mottled("leaves", (0.05, 0.16, 0.03), (0.16, 0.3, 0.07), 2.5, 0.8, 0.3)
    sign_mats = [materials.plain("sign_blue", (0.03, 0.12, 0.5), 0.4), materials.plain("sign_red", (0.6, 0.03, 0.03), 0.4)]
    objs = []
    walk = ROAD_HALF + 0.15
    for side in (-1, 1):
        xs = np.arange(X_START + 6, X_END - 5, 11.0)
        for k, x in enumerate(xs + rng.uniform(-2, 2, len(xs))):
            if rng.random() < 0.25:
                continue
            (px, py), _ = street.frame_at(x, side * (walk + 2.2))
            objs += _tree(f"tree_{side}_{k}", (px, py, KERB_H), rng, bark, leaves, col)
        for k, x in enumerate(np.arange(X_START + (0 if side > 0 else 12), X_END, 24.0)):
            (px, py), yaw = street.frame_at(x, side * (walk + 0.5))
            objs.append(cylinder(f"lamp_{side}_{k}", 0.08, 6.5, (px, py, KERB_H), metal, 10, col))
            (ax, ay), _ = street.frame_at(x, side * (walk - 0.7))
            objs.append(box(f"lamp_arm_{side}_{k}", (0.3, 2.4, 0.12), ((px + ax) / 2, (py + ay) / 2, KERB_H + 6.4), yaw, metal, col))
    for k, x in enumerate(rng.uniform(8, 150, 5)):
        side = 1 if k % 2 else -1
        (px, py), yaw = street.frame_at(x, side * (walk + 0.6))
        objs.append(cylinder(f"sign_pole_{k}", 0.04, 2.6, (px, py, KERB_H), metal, 8, col))
        objs.append(box(f"sign_{k}", (0.04, 0.7, 0.7), (px, py, KERB_H + 2.1), yaw, sign_mats[k % 2], col))
    return objs


def _parked_cars(street: Street, rng, col, keep_clear_until: float):
    """Cars along both parking strips; the right one stays clear along the drive so that
    laterally shifted cameras (up to 3 m right) never sit inside a car."""
    objs = []
    kinds = sorted(PRESETS)
    for side in (-1, 1):
        x = (keep_clear_until + 10.0) if side < 0 else rng.uniform(4, 10)
        k = 0
        while x < 150:
            if rng.random() < 0.75:
                spec = PRESETS[kinds[rng.integers(len(kinds))]]
                paint = PAINTS[rng.integers(len(PAINTS))]
                car = build_car(f"parked_{side}_{k}", spec, paint, col)
                (px, py), yaw = street.frame_at(x, side * PARK_OFFSET)
                place(car, (px, py, car["wlh"][2] / 2), yaw + (math.pi if side > 0 else 0.0))
                objs.append(car)
                k += 1
            x += rng.uniform(6.0, 11.0)
    return objs


def _sun(overcast: bool, elevation: float, azimuth: float):
    if overcast:
        return None, None
    light = bpy.data.lights.new("sun", "SUN")
    light.energy = 3.2
    light.angle = math.radians(1.0)
    obj = bpy.data.objects.new("sun", light)
    bpy.context.scene.collection.objects.link(obj)
    towards_sun = Vector((math.cos(elevation) * math.cos(azimuth), math.cos(elevation) * math.sin(azimuth), math.sin(elevation)))
    obj.rotation_euler = (-towards_sun).to_track_quat("-Z", "Y").to_euler()
    return obj, -np.array(towards_sun)


def build_street(seed: int, overcast: bool, drive_end_x: float, material_jitter: float = 0.0) -> Street:
    """Build the whole static scene into the current (empty) Blender scene; ``material_jitter``
    scales each ground material's colours by a seeded factor per channel within 1 +/- it (0: the
    built-in colours; its own random stream, so the street's layout does not change with it)."""
    rng = np.random.default_rng(seed)
    street = Street(amp=float(rng.uniform(1.0, 2.5)), period=float(rng.uniform(140, 200)))
    col = bpy.data.collections.new("background")
    bpy.context.scene.collection.children.link(col)
    tints = np.random.default_rng([seed, 1]).uniform(1 - material_jitter, 1 + material_jitter, (len(GROUND), 3))
    street.background += _road(street, col, dict(zip(GROUND, tints, strict=True)))
    street.background += _buildings(street, rng, col)
    street.background += _props(street, rng, col)
    street.parked = _parked_cars(street, rng, col, drive_end_x)
    street.background += street.parked
    elevation, azimuth = math.radians(38.0), math.radians(rng.uniform(35, 60))
    _, street.sun_direction = _sun(overcast, elevation, azimuth)
    scene = bpy.context.scene
    scene.world = materials.sky_world(overcast, elevation, azimuth - math.pi / 2, 0.35 if not overcast else 1.1)
    return street
