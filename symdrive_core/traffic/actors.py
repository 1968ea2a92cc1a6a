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
from ..scene.road import Road
from .assets import Asset
from .fcd import Track, sample_track


def track_poses(track: Track, asset: Asset, road: Road, times: np.ndarray, net_offset=(0.0, 0.0)) -> list[Pose | None]:
    centre, yaw, present = sample_track(track, times, asset.length, net_offset)
    z = road.ground_height(centre[:, :2]) + 0.5 * asset.wlh[2]
    return [Pose(np.array([centre[i, 0], centre[i, 1], z[i]]), quat_from_yaw(float(yaw[i]))) if present[i]
            else None for i in range(len(times))]


def _relative(path: Path | None, root: Path) -> str | None:
    return None if path is None else os.path.relpath(path, root)


def traffic_actors(tracks: dict[str, Track], assets: dict[str, Asset], road: Road, times: np.ndarray,
                   package_root: Path, net_offset=(0.0, 0.0)) -> list[Actor]:
    """Inserted actors, in order of first appearance; asset paths relative to ``package_root``;
    ``net_offset``: the SUMO network's offset from the scene frame."""
    actors = []
    ordered = sorted(tracks.values(), key=lambda tr: (tr.times[0], tr.vehicle))
    for track in ordered:
        asset = assets[track.vtype]
        poses = track_poses(track, asset, road, times, net_offset)
        if all(p is None for p in poses):
            continue
        actors.append(Actor(track.vehicle, "inserted", _relative(asset.splats, package_root),
                            _relative(asset.mesh, package_root), poses, asset.wlh.copy(), len(actors) + 1))
    return actors
