"""The points a package's reconstruction starts from (and its ground fit stands on), of its
training frames only.

Held-out frames score the reconstruction, so nothing of theirs may reach its start: a LiDAR's
returns recorded at a held-out frame (coloured from that frame's image) are left out, and points
are triangulated from the training frames' images only. Points of no one frame (a COLMAP
model's, a splat file's) come as they are.

A drive's LiDAR returns start the reconstruction where the scanner reaches; its beams stop a few
degrees above the horizon and a few tens of metres out, so the tops of trees and buildings and
the far street have no return. There the points triangulated from the images join them (as
Street Gaussians starts its background): those farther than ``beyond_lidar_m`` from every return.
The ground is fitted to the returns alone, which are metric and dense on the road.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from .frames import split_heldout
from .package import Source
from .triangulate import Triangulated, triangulate


@dataclass(frozen=True)
class StartPointsConfig:
    triangulate_beyond_lidar: bool = True  # a drive's LiDAR returns joined by triangulated points
    beyond_lidar_m: float = 0.5  # where the nearest return is farther than this


def training_frames(src: Source, heldout_every: int | None) -> list[int]:
    """The frames a package imported with ``--heldout-every`` trains on (all without it)."""
    return split_heldout(len(src.grouped.frame_keys), heldout_every)[0]


def drop_heldout_returns(src: Source, train: list[int]) -> int:
    """Leave out of ``src``'s points those seen in frames not in ``train``; how many were."""
    if src.point_frames is None:
        return 0
    keep = np.isin(src.point_frames, train)
    src.points, src.point_frames = src.points[keep], src.point_frames[keep]
    if src.colors is not None:
        src.colors = src.colors[keep]
    return int((~keep).sum())


def start_points(src: Source, near: Path, heldout_every: int | None, cfg: StartPointsConfig = StartPointsConfig(),
                 log=print) -> None:
    """Make ``src``'s points the start of its training frames: a held-out frame's returns left
    out, a source without points or splats (and with images) given triangulated ones, a drive's
    returns joined by those beyond their reach; ``log`` says what was done (a line each).
    Triangulation works beside ``near``."""
    train = training_frames(src, heldout_every)
    dropped = drop_heldout_returns(src, train)
    if dropped:
        log(f"left out {dropped} LiDAR returns of held-out frames from the start points")
    lidar = src.point_frames is not None and cfg.triangulate_beyond_lidar
    if (src.points is not None or src.splats is not None) and not lidar:
        return
    if any(v.image is None for row in src.grouped.table for v in row):
        return
    t0 = time.perf_counter()
    n = len(train) * len(src.grouped.cameras)
    log(f"triangulating points from {n} images of the training frames with the poses fixed"
        + (f" (to join the LiDAR's where it has no return within {cfg.beyond_lidar_m:g} m)" if lidar else ""))
    try:
        tri = triangulate(src.grouped, near, frames=train)
    except InputError as exc:
        if not lidar:
            raise
        log(f"note: {exc}; the start is the LiDAR's returns alone")
        return
    done = f"{tri.record['mean_reprojection_error_px']:.2f} px mean reprojection error, {time.perf_counter() - t0:.1f} s"
    if lidar:
        joined = join_beyond_lidar(src, tri, cfg.beyond_lidar_m)
        log(f"triangulated {tri.record['points']} points ({done}); {joined} beyond the LiDAR's reach join its "
            f"{len(src.points) - joined} returns")
    else:
        src.points, src.colors, src.point_frames = tri.points, tri.colors, None
        src.notes["triangulated"] = tri.record
        log(f"triangulated {tri.record['points']} points ({done})")


def nearest_distance(points: np.ndarray, to: np.ndarray, chunk: int = 256) -> np.ndarray:
    """Distance [N] from each of ``points`` to the nearest of ``to`` (float64, differences taken
    directly rather than through the matrix-product expansion, exact far from the origin)."""
    import torch

    if len(to) == 0:
        return np.full(len(points), np.inf)
    q, ref = torch.from_numpy(np.asarray(points, np.float64)), torch.from_numpy(np.asarray(to, np.float64))
    out = torch.empty(len(q), dtype=torch.float64)
    for s in range(0, len(q), chunk):
        out[s:s + chunk] = torch.cdist(q[s:s + chunk], ref, compute_mode="donot_use_mm_for_euclid_dist").amin(1)
    return out.numpy()


def join_beyond_lidar(src: Source, tri: Triangulated, distance_m: float) -> int:
    """Add to ``src``'s LiDAR points the triangulated ones farther than ``distance_m`` from every
    return (marked as of no frame, -1); how many joined."""
    far = nearest_distance(tri.points, src.points) > distance_m
    src.points = np.concatenate([src.points, tri.points[far]])
    src.colors = np.concatenate([src.colors, tri.colors[far]])
    src.point_frames = np.concatenate([src.point_frames, np.full(int(far.sum()), -1)])
    src.notes["triangulated"] = {**tri.record, "beyond_lidar_m": distance_m, "joined": int(far.sum())}
    return int(far.sum())
