"""A metric drive round a bend, as an SfM reconstruction would see it: few road points, many on the
kerbs and sidewalks 15 cm up, parked cars beside the lane, facades; the cameras 1.65 m above the
road with a centimetre of suspension bounce. Written in a random rigid frame (metric poses)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from symdrive_core import conventions
from symdrive_core.importers.similarity import apply_camera, apply_points, make_similarity
from symdrive_core.io.images import write_image
from symdrive_core.rotations import quat_normalize, quat_to_matrix

from ..conftest import look_at_c2w
from .demo_formats import World

CAMERA_HEIGHT = 1.65  # KITTI's camera above the road, metres
RADIUS = 60.0  # the bend's radius, metres
LANE = -1.75  # the cameras' lateral offset from the road's centre line (right lane)
W, H = 32, 24  # the recorded images' size (their content is not used)


def _arc(phi, lateral):
    """Points ``lateral`` metres left of the centre line at bend angle ``phi`` (turning left)."""
    r = RADIUS - lateral
    return np.stack([r * np.sin(phi), RADIUS - r * np.cos(phi)], -1)


def street_points(rng, phi_max: float) -> tuple[np.ndarray, dict[str, slice]]:
    """Points in the street's own frame (road at z = 0), and which rows are which surface."""
    parts = {}

    def along(n, lat_lo, lat_hi, z):
        phi = rng.uniform(-0.05, phi_max + 0.05, n)
        lat = rng.uniform(lat_lo, lat_hi, n)
        return np.column_stack([_arc(phi, lat), z])

    road = along(400, -5.0, 5.0, rng.normal(0, 0.01, 400))
    kerbs = np.concatenate([along(900, -9.0, -5.0, 0.15 + rng.normal(0, 0.01, 900)),
                            along(900, 5.0, 9.0, 0.15 + rng.normal(0, 0.01, 900))])
    facades = np.concatenate([along(1000, -12.0, -12.0, rng.uniform(0, 10, 1000)),
                              along(1000, 12.0, 12.0, rng.uniform(0, 10, 1000))])
    cars = []
    for phi0 in np.linspace(0.05, phi_max - 0.05, 10):  # parked along the right edge
        n = 150
        phi = phi0 + rng.uniform(0, 4.5 / RADIUS, n)
        cars.append(np.column_stack([_arc(phi, rng.uniform(-4.8, -3.0, n)), rng.uniform(0.2, 1.5, n)]))
    cars = np.concatenate(cars)
    rows = 0
    for name, p in (("road", road), ("kerbs", kerbs), ("facades", facades), ("cars", cars)):
        parts[name] = slice(rows, rows + len(p))
        rows += len(p)
    return np.concatenate([road, kerbs, facades, cars]), parts


def street_cameras(rng, frames: int, phi_max: float) -> np.ndarray:
    """OpenCV camera-to-world [F, 4, 4] along the right lane, pitched 1 degree down, bouncing 1 cm."""
    phi = np.linspace(0, phi_max, frames)
    eye = np.column_stack([_arc(phi, LANE), CAMERA_HEIGHT + rng.normal(0, 0.01, frames)])
    ahead = np.column_stack([_arc(phi + 10 / RADIUS, LANE), eye[:, 2] - 10 * np.tan(np.radians(1.0))])
    return np.stack([look_at_c2w(e, a) for e, a in zip(eye, ahead)])


def curved_world(tmp: Path, seed: int = 0, frames: int = 60, phi_max: float = 1.2) -> tuple[World, dict]:
    """The street (about 72 m of a 60 m bend) in a random metric frame, with blank images in ``tmp``."""
    rng = np.random.default_rng(seed)
    pts, parts = street_points(rng, phi_max)
    c2w = street_cameras(rng, frames, phi_max)
    S = make_similarity(1.0, quat_to_matrix(quat_normalize(rng.normal(size=4))), rng.normal(size=3) * 500)
    image = tmp / "blank.png"
    write_image(image, np.full((H, W, 3), 0.5, np.float32))
    world = World(S=S, names=[f"{i:06d}.png" for i in range(frames)], images=[image] * frames,
                  K=conventions.intrinsics(20.0, 20.0, W / 2, H / 2), width=W, height=H,
                  c2w=np.stack([apply_camera(S, c) for c in c2w]), c2w_demo=c2w, splats=None,
                  points=apply_points(S, pts), colors=np.full((len(pts), 3), 0.5))
    return world, parts
