"""Scene packages cut from the tiny test package with one string changed, and a snapshot of
every file under a folder, to see what a run created or deleted."""

from __future__ import annotations

import json
import os
from pathlib import Path

from symdrive_core.io.ply import write_splats
from tests.conftest import manifest_dict, random_gaussians


def write_package(root: Path, edit=None, n_frames: int = 2) -> Path:
    """A valid tiny package at ``root``; ``edit(d)`` changes its manifest dict first."""
    root.mkdir(parents=True, exist_ok=True)
    d = manifest_dict(n_frames=n_frames)
    write_splats(root / "background.ply", random_gaussians(200, 0, 1, (10, 0, 1), 3.0))
    write_splats(root / "car_0.ply", random_gaussians(50, 1, 10, spread=0.8))
    if edit is not None:
        edit(d)
    (root / "manifest.json").write_text(json.dumps(d))
    return root / "manifest.json"


def snapshot(folder: Path) -> dict[str, int]:
    """Every file and link under ``folder`` with its mtime (links not followed)."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(folder):
        for name in filenames + [d for d in dirnames if os.path.islink(os.path.join(dirpath, d))]:
            p = os.path.join(dirpath, name)
            out[os.path.relpath(p, folder)] = os.lstat(p).st_mtime_ns
    return out


def created_outside(before: dict, after: dict, *allowed: str) -> list[str]:
    """Files that appeared, outside the ``allowed`` sub-folders."""
    return [p for p in after if p not in before and not any(p == a or p.startswith(a.rstrip("/") + "/")
                                                              for a in allowed)]
