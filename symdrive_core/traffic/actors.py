"""Turn simulated tracks into manifest actors with one pose per frame.

Each track is resampled at the frames' simulation times: box centre linearly, heading along the
shortest arc. The vehicle stands on the road: its origin (box centre) is half its height above
the road surface under it. A frame before the vehicle entered or after it left gets ``None``;
a vehicle seen in no frame is not an actor.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..rotations import quat_from_yaw
from ..scene import Actor, Pose
from .assets import Asset
from .fcd import Track
from .road import Road

TIME_EPS = 1e-6


def resample(track: Track, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(present [F] bool, centre [F, 2], yaw [F]) at ``times``."""
    present = (times >= track.times[0] - TIME_EPS) & (times <= track.times[-1] + TIME_EPS)
    t = np.clip(times, track.times[0], track.times[-1])
    if len(track.times) == 1:
        return present, np.repeat(track.centre, len(times), axis=0), np.full(len(times), track.yaw[0])
    centre = np.stack([np.interp(t, track.times, track.centre[:, i]) for i in range(2)], axis=1)
    yaw = np.interp(t, track.times, np.unwrap(track.yaw))
    return present, centre, yaw


def track_poses(track: Track, asset: Asset, road: Road, times: np.ndarray) -> list[Pose | None]:
    present, centre, yaw = resample(track, times)
    z = road.ground_height(centre) + 0.5 * asset.wlh[2]
    return [Pose(np.array([centre[i, 0], centre[i, 1], z[i]]), quat_from_yaw(float(yaw[i]))) if present[i]
            else None for i in range(len(times))]


def _relative(path: Path | None, root: Path) -> str | None:
    return None if path is None else os.path.relpath(path, root)


def traffic_actors(tracks: dict[str, Track], assets: dict[str, Asset], road: Road, times: np.ndarray,
                   package_root: Path) -> list[Actor]:
    """Inserted actors, in order of first appearance; asset paths relative to ``package_root``."""
    actors = []
    ordered = sorted(tracks.values(), key=lambda tr: (tr.times[0], tr.vehicle))
    for track in ordered:
        asset = assets[track.vtype]
        poses = track_poses(track, asset, road, times)
        if all(p is None for p in poses):
            continue
        actors.append(Actor(track.vehicle, "inserted", _relative(asset.splats, package_root),
                            _relative(asset.mesh, package_root), poses, asset.wlh.copy(), len(actors) + 1))
    return actors
