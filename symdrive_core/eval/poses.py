"""Tracked boxes against the truth: a known jitter of exact boxes (what a tracker's error looks
like, at a size one states) and the error of poses against the true ones, for measuring what a
pose refinement recovers (:mod:`symdrive_core.optim.pose_refine`).
"""

from __future__ import annotations

import numpy as np

from ..rotations import quat_from_yaw, quat_multiply
from ..scene.poses import Pose, yaw_of


def jittered(poses: list[Pose | None], translation_m: float, yaw_rad: float,
             rng: np.random.Generator) -> list[Pose | None]:
    """``poses`` each moved by exactly ``translation_m`` in a random horizontal direction and turned
    by ``yaw_rad`` about the world's up, either way (independently per frame): the jitter's mean
    error is then the stated size itself."""
    out: list[Pose | None] = []
    for p in poses:
        if p is None:
            out.append(None)
            continue
        a = rng.uniform(0.0, 2.0 * np.pi)
        turn = quat_from_yaw(yaw_rad * rng.choice([-1.0, 1.0]))
        out.append(Pose(p.translation + translation_m * np.array([np.cos(a), np.sin(a), 0.0]),
                        quat_multiply(turn, p.rotation)))
    return out


def pose_errors(poses: list[Pose | None], truth: list[Pose | None], frames: list[int] | None = None) -> dict:
    """Mean and largest distance of the box centres (cm) and heading difference (degrees) over the
    frames both have (of ``frames``, default all)."""
    frames = range(len(truth)) if frames is None else frames
    pairs = [(poses[f], truth[f]) for f in frames if poses[f] is not None and truth[f] is not None]
    cm = np.array([100.0 * np.linalg.norm(p.translation - t.translation) for p, t in pairs])
    turn = np.array([yaw_of(p.rotation) - yaw_of(t.rotation) for p, t in pairs])
    deg = np.degrees(np.abs(np.angle(np.exp(1j * turn))))
    return {"frames": len(pairs), "mean_cm": float(cm.mean()), "max_cm": float(cm.max()),
            "mean_deg": float(deg.mean()), "max_deg": float(deg.max())}
