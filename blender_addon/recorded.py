"""An existing actor's recorded track, as it travels with its Blender object, and its edit (numpy only).

A vehicle the drive recorded is imported keyed on its poses; the track it was recorded on is kept
on the actor root (``symdrive.recorded_poses``, JSON) in the package's frame: the Blender frame of
the package's first frame and one pose (or null) per package frame. Export compares the poses it
evaluates with that track, so the backend learns what the artist removed, moved or retimed.
A refined actor's tracked boxes (``symdrive.tracked_poses``) are kept the same way and exported as kept.
"""

from __future__ import annotations

import json

import numpy as np

from .core import scene as scene_pkg


def encode(frame_start: int, poses: list) -> str:
    """The JSON kept on the actor root: the poses as the package wrote them, from Blender frame ``frame_start``."""
    return json.dumps(
        {"frame_start": int(frame_start), "poses": [None if p is None else p.to_json() for p in poses]}
    )


def at_frames(text: str, frame_numbers) -> list:
    """The kept pose at each Blender frame of ``frame_numbers`` (None outside the kept span)."""
    data = json.loads(text)
    start, poses = data["frame_start"], data["poses"]
    out = []
    for f in frame_numbers:
        p = poses[f - start] if 0 <= f - start < len(poses) else None
        out.append(
            None if p is None else scene_pkg.Pose(np.array(p["translation"]), np.array(p["rotation"]))
        )
    return out


def _same(pose, recorded, tolerance_m: float) -> bool:
    if pose is None or recorded is None:
        return pose is None and recorded is None
    return pose.close_to(recorded, tolerance_m)


def against_recorded(poses: list, recorded: list, tolerance_m: float = 1e-3) -> tuple[list, list | None]:
    """(poses, recorded poses) to export: a frame left as recorded keeps the recorded pose exactly
    (Blender keys hold float32, which would otherwise read as a tiny edit), and the recorded poses
    go with the actor only when an edit left them in some frame."""
    kept = [r if _same(p, r, tolerance_m) else p for p, r in zip(poses, recorded, strict=True)]
    edited = any(not _same(p, r, tolerance_m) for p, r in zip(poses, recorded, strict=True))
    return kept, (recorded if edited else None)
