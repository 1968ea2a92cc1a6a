"""The points a package's reconstruction starts from (and its ground fit stands on), of its
training frames only.

Held-out frames score the reconstruction, so nothing of theirs may reach its start: a LiDAR's
returns recorded at a held-out frame (coloured from that frame's image) are left out, and points
are triangulated from the training frames' images only. Points of no one frame (a COLMAP
model's, a splat file's) come as they are.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .frames import split_heldout
from .package import Source
from .triangulate import Triangulated, triangulate


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


def triangulate_training(src: Source, near: Path, train: list[int]) -> Triangulated:
    """Points triangulated from the images of the ``train`` frames, become ``src``'s points."""
    tri = triangulate(src.grouped, near, frames=train)
    src.points, src.colors, src.point_frames = tri.points, tri.colors, None
    src.notes["triangulated"] = tri.record
    return tri
