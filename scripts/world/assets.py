"""Vehicle assets in the 3DRealCar layout: ``mesh.obj`` (+ ``mesh.mtl``), ``wlh.json`` and a
splat PLY sampled from the mesh surface with albedo colours.

Albedo shown through the sRGB curve is what a car looks like under even white studio light,
which is how 3DRealCar cars are captured; placing such an asset in a sunlit street without
harmonization looks wrong in exactly the way the insertion task has to fix.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from symdrive_core import conventions
from symdrive_core.insertion.surface import sample_surface, surface_splats, surfel_spacing, triangle_areas
from symdrive_core.io.atomic import write_text_atomic
from symdrive_core.io.ply import write_splats
from symdrive_core.world.obj import write_obj

from .meshdata import object_triangles


def export_car(obj, folder: Path, n_splats: int, seed: int) -> dict:
    """Write the asset folder for a car object built at the origin; returns its summary."""
    folder.mkdir(parents=True, exist_ok=True)
    mesh = obj.data
    verts = np.array([v.co[:] for v in mesh.vertices])
    faces = [tuple(p.vertices) for p in mesh.polygons]
    face_mats = [p.material_index for p in mesh.polygons]
    slots = [(m.name, tuple(m["albedo"])) for m in mesh.materials]
    write_obj(folder / "mesh.obj", verts, faces, face_mats, slots)

    v, tris, albedo = object_triangles(obj, world=False)
    pts, normals, tri = sample_surface(v, tris, n_splats, np.random.default_rng(seed))
    spacing = surfel_spacing(float(triangle_areas(v, tris).sum()), n_splats)
    splats = surface_splats(pts, normals, conventions.linear_to_srgb(albedo[tri]), 1.2 * spacing)
    write_splats(folder / "splats.ply", splats)

    wlh = [round(float(x), 4) for x in obj["wlh"]]
    info = {"wlh": wlh, "units": "metres", "kind": obj.get("kind", "car"),
            "frame": "3DRealCar: X forward (length), Y left, Z up, origin at the bounding-box centre",
            "mesh": "mesh.obj", "splats": "splats.ply", "lighting": "studio (albedo colours)"}
    write_text_atomic(folder / "wlh.json", json.dumps(info, indent=1) + "\n")
    return info
