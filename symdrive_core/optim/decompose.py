"""Recorded vehicles as Gaussian sets of their own (Street Gaussians, the paper's base).

A static 3DGS smears a moving car along its path. Instead each ``existing`` actor with a box
(``wlh``) and recorded poses gets its own Gaussians in its local 3DRealCar frame, placed at every
frame by ``mu_w = R(t) mu_l + T(t)`` (:mod:`symdrive_core.splat.compose`), and fitted jointly with
the background. Two rules keep the roles apart: a vehicle's Gaussians stay inside its (padded) box,
and the background keeps none inside the volume any recorded box sweeps (above a thin layer of
road under the wheels), so the background cannot learn a car. A vehicle starts where the training
views' depth measured its surface, each return carried into its frame by the box of the frame that
measured it (the points the background may not keep), and on its box's faces where nothing did.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..conventions import pixel_rays_camera
from ..scene import Actor, Manifest
from ..scene.depth import measured
from ..scene.poses import Pose

BOX_PAD = 0.1  # a vehicle's Gaussians may reach 10 % beyond its box (mirrors, wheels, box error)
ROAD_LAYER_M = 0.15  # the background keeps what lies this close above a box's underside (the road)


@dataclass
class Track:
    """One recorded vehicle to decompose: its box and where the drive saw it."""

    actor_id: str
    instance_id: int
    wlh: np.ndarray  # width, length, height (metres)
    poses: list[Pose | None]  # recorded, one per frame

    @property
    def half(self) -> np.ndarray:
        """Half extents along the local x (length), y (width), z (height)."""
        w, length, h = self.wlh
        return 0.5 * np.array([length, w, h])

    def frames(self) -> list[int]:
        return [f for f, p in enumerate(self.poses) if p is not None]

    def pose_at(self, frame: int) -> Pose | None:
        """The box at ``frame``; None where the drive did not see the vehicle (or past its poses)."""
        return self.poses[frame] if frame < len(self.poses) else None


def tracks(manifest: Manifest) -> list[Track]:
    """The package's recorded vehicles that can be decomposed: ``existing`` actors with a box and a
    recorded pose at some frame."""
    return [Track(a.id, a.instance_id, np.asarray(a.wlh, np.float64), [a.recorded_pose(f) for f in range(len(a.poses))])
            for a in manifest.actors if _decomposable(a)]


def _decomposable(a: Actor) -> bool:
    return a.kind == "existing" and a.wlh is not None and any(
        a.recorded_pose(f) is not None for f in range(len(a.poses)))


def inside_box(local: np.ndarray, half: np.ndarray, pad: float = BOX_PAD, floor_m: float = 0.0) -> np.ndarray:
    """[N] whether local points lie in the box padded by ``pad`` (a fraction), its floor raised by
    ``floor_m``."""
    lim = half * (1.0 + pad)
    return (np.abs(local[:, 0]) <= lim[0]) & (np.abs(local[:, 1]) <= lim[1]) & (local[:, 2] <= lim[2]) & (
        local[:, 2] >= -half[2] + floor_m)


def in_swept_boxes(points: np.ndarray, tracks_: list[Track]) -> np.ndarray:
    """[N] whether world points fall in any track's box at any frame, the road layer under it
    excluded: what the background must not hold."""
    points = np.asarray(points, np.float64)
    hit = np.zeros(len(points), bool)
    for t in tracks_:
        for p in (t.poses[f] for f in t.frames()):
            centre_dist = np.abs(points - p.translation).max(1)
            near = np.nonzero(centre_dist <= np.linalg.norm(t.half) * (1.0 + BOX_PAD))[0]
            if len(near):
                local = (points[near] - p.translation) @ p.R
                hit[near[inside_box(local, t.half, pad=0.0, floor_m=ROAD_LAYER_M)]] = True
    return hit


def box_surface(track: Track, n: int, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """``n`` points on the faces of the track's box (a car's surface is near its box), in its local
    frame, and the Gaussian size their spacing gives (:func:`colour_from_views` colours them)."""
    half = track.half
    areas = np.array([half[1] * half[2], half[0] * half[2], half[0] * half[1]]).repeat(2)
    face = rng.choice(6, n, p=areas / areas.sum())
    pts = rng.uniform(-1.0, 1.0, (n, 3)) * half * 0.95
    axis, sign = face // 2, np.where(face % 2 == 0, 1.0, -1.0)
    pts[np.arange(n), axis] = sign * half[axis] * 0.95
    return pts, 0.5 * float(np.sqrt(2.0 * areas.sum() / max(n, 1)))


def measured_points(track: Track, views) -> tuple[np.ndarray, np.ndarray]:
    """([M, 3] local points, [M, 3] colours): the depth pixels of the views (frame, K,
    world_to_camera, image [H, W, 3], depth [H, W] with NaN / inf where nothing was measured) that
    fall in the track's box at their own frame, above the road layer under it. Carried into the
    vehicle's frame by the box of the frame that measured them, the returns on a car that drives
    land on its surface as those of a parked one do (Street Gaussians starts each vehicle from its
    LiDAR points); the pixel's colour is the surface's."""
    pts, cols = [], []
    reach = np.linalg.norm(track.half)
    for frame, K, w2c, image, depth in views:
        p = track.pose_at(frame)
        if p is None or depth is None:
            continue
        v, u = np.nonzero(measured(depth))
        if not len(v):
            continue
        cam = pixel_rays_camera(K, u, v) * depth[v, u, None].astype(np.float64)
        world = (cam - w2c[:3, 3]) @ w2c[:3, :3]
        near = np.nonzero(np.abs(world - p.translation).max(1) <= reach)[0]
        local = (world[near] - p.translation) @ p.R
        inside = inside_box(local, track.half, pad=0.0, floor_m=ROAD_LAYER_M)
        pts.append(local[inside])
        cols.append(image[v[near[inside]], u[near[inside]]])
    if not pts:
        return np.zeros((0, 3)), np.zeros((0, 3))
    return np.concatenate(pts), np.concatenate(cols).astype(np.float64)


def colour_from_views(track: Track, local: np.ndarray, views) -> np.ndarray:
    """[N, 3] median colour of each local point over the views (frame, K, world_to_camera, image
    [H, W, 3]) where the track is present and the point projects inside the image; grey where none.
    A start the fit can reach: from grey, colour moves slower than opacity, and Gaussians that
    must change colour much turn transparent instead."""
    samples = [[] for _ in range(len(local))]
    for frame, K, w2c, image in views:
        p = track.pose_at(frame)
        if p is None:
            continue
        cam = p.apply(local) @ w2c[:3, :3].T + w2c[:3, 3]
        h, w = image.shape[:2]
        z = np.maximum(cam[:, 2], 1e-6)
        u, v = cam[:, 0] / z * K[0, 0] + K[0, 2], cam[:, 1] / z * K[1, 1] + K[1, 2]
        ok = np.nonzero((cam[:, 2] > 0.1) & (u >= 0) & (u < w) & (v >= 0) & (v < h))[0]
        for k, c in zip(ok, image[v[ok].astype(int), u[ok].astype(int)]):
            samples[k].append(c)
    return np.array([np.median(s, axis=0) if s else np.full(3, 0.5) for s in samples], np.float64)
