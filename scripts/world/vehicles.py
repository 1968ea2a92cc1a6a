"""Procedural cars in the 3DRealCar frame: X forward along the length, Z up, origin at the
centre of the bounding box (underside at z = -h/2), metric size.

A car is one mesh object: an extruded side profile for the body, a narrower extruded cabin
with glass, four wheels and light clusters, each part with its own material slot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import materials
from .geometry import box_geometry, cylinder_geometry, extrude_profile, mesh_object


@dataclass(frozen=True)
class CarSpec:
    kind: str
    length: float
    width: float
    height: float
    wheel_radius: float
    belt: float  # height of the bonnet/boot line above the ground, fraction of the height
    cabin: tuple[float, float]  # rear and front end of the cabin base, fraction of the length


PRESETS = {
    "sedan": CarSpec("sedan", 4.60, 1.80, 1.45, 0.32, 0.55, (-0.28, 0.18)),
    "suv": CarSpec("suv", 4.70, 1.90, 1.75, 0.37, 0.56, (-0.44, 0.20)),
    "hatchback": CarSpec("hatchback", 4.00, 1.74, 1.50, 0.31, 0.54, (-0.46, 0.14)),
}
# Body shapes of the moving traffic (world.traffic): none of them is parked, so a moving car is
# never mistaken for a parked one. Kept apart from PRESETS, whose draws place the parked cars.
TRAFFIC_PRESETS = {
    "van": CarSpec("van", 5.00, 1.95, 1.95, 0.36, 0.50, (-0.48, 0.30)),
    "coupe": CarSpec("coupe", 4.40, 1.82, 1.30, 0.32, 0.58, (-0.22, 0.12)),
    "wagon": CarSpec("wagon", 4.80, 1.82, 1.50, 0.32, 0.55, (-0.47, 0.16)),
}
# Paint of the three exported assets (linear RGB).
ASSET_PAINTS = {"sedan": (0.55, 0.04, 0.03), "suv": (0.04, 0.1, 0.35), "hatchback": (0.7, 0.7, 0.68)}

# Slots: 0 paint, 1 glass, 2 tyre, 3 trim, 4 headlight, 5 tail light.
PAINT, GLASS, TYRE, TRIM, HEAD, TAIL = range(6)


def car_materials(name: str, paint_rgb) -> list:
    return [
        materials.plain(f"{name}_paint", paint_rgb, roughness=0.3, metallic=0.4),
        materials.plain(f"{name}_glass", (0.04, 0.05, 0.06), roughness=0.05),
        materials.plain(f"{name}_tyre", (0.025, 0.025, 0.025), roughness=0.9),
        materials.plain(f"{name}_trim", (0.08, 0.08, 0.085), roughness=0.5),
        materials.plain(f"{name}_head", (0.92, 0.92, 0.88), roughness=0.1),
        materials.plain(f"{name}_tail", (0.65, 0.03, 0.03), roughness=0.2),
    ]


def car_geometry(spec: CarSpec):
    """Vertices [V,3], faces and per-face material slots, in the 3DRealCar frame."""
    L, W, H, r = spec.length, spec.width, spec.height, spec.wheel_radius
    clear, belt = 0.55 * r, spec.belt * H
    verts, faces, mats = [], [], []

    def add(v, f, m):
        off = len(verts)
        verts.extend(v)
        faces.extend(tuple(i + off for i in face) for face in f)
        mats.extend(m if isinstance(m, list) else [m] * len(f))

    body = [(-L / 2, clear + 0.12), (-L / 2 + 0.2, clear), (L / 2 - 0.25, clear), (L / 2, clear + 0.15),
            (L / 2, belt - 0.12), (L / 2 - 0.12, belt), (-L / 2 + 0.08, belt), (-L / 2, belt - 0.06)]
    v, f, edges = extrude_profile(body, -W / 2, W / 2)
    add(v, f, [TRIM if e in (0, 1, 2) else PAINT for e in edges])

    xr, xf = spec.cabin[0] * L, spec.cabin[1] * L
    rise = H - belt
    cabin = [(xr, belt), (xf, belt), (xf - 1.1 * rise, H), (xr + 0.45 * rise, H)]
    cw = 0.43 * W
    v, f, edges = extrude_profile(cabin, -cw, cw)
    add(v, f, [PAINT if e == 2 else GLASS for e in edges])

    base = 0.62 * L / 2
    for x in (-base, base):
        for y0, y1 in ((W / 2 - 0.24, W / 2 - 0.01), (-W / 2 + 0.01, -W / 2 + 0.24)):
            v, f = cylinder_geometry(r, y0, y1, 16, axis="y", center=(x, r))
            add(v, f, TYRE)
    for y in (W / 2 - 0.33, -W / 2 + 0.33):
        v, f = box_geometry(L / 2 - 0.03, L / 2 + 0.0, y - 0.17, y + 0.17, belt - 0.2, belt - 0.08)
        add(v, f, HEAD)
        v, f = box_geometry(-L / 2, -L / 2 + 0.03, y - 0.16, y + 0.16, belt - 0.22, belt - 0.1)
        add(v, f, TAIL)

    verts = np.asarray(verts, dtype=np.float64)
    lo, hi = verts.min(0), verts.max(0)
    verts -= 0.5 * (lo + hi)  # origin at the bounding-box centre
    return verts, faces, mats


def build_car(name: str, spec: CarSpec, paint_rgb, collection=None):
    """A car mesh object at the origin; ``obj["wlh"]`` is its measured (width, length, height)."""
    verts, faces, mats = car_geometry(spec)
    obj = mesh_object(name, verts, faces, car_materials(name, paint_rgb), mats, collection)
    ext = verts.max(0) - verts.min(0)
    obj["wlh"] = [float(ext[1]), float(ext[0]), float(ext[2])]
    return obj
