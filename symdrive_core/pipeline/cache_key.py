"""The key a run's outputs are cached under: everything that changes the result, and nothing else.

A run reuses a folder's outputs only when this key matches the one they were made under:
the manifest, the identity of every file it names, ground truth included (size, mtime, inode,
and the bytes of small files), the plan and stage options, the device, the code and the restorer weights. Files in the
package that the manifest does not name (its default output folder among them) play no part.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
from dataclasses import asdict
from pathlib import Path

SMALL_FILE = 1 << 20  # files up to this size are keyed by their bytes, larger ones by their identity
_PACKAGE = Path(__file__).resolve().parents[1]


def file_identity(path: Path) -> str:
    """Size, mtime and inode; and for a small file, the hash of its bytes."""
    try:
        st = os.stat(path)
    except OSError:
        return "missing"
    ident = f"{st.st_size}:{st.st_mtime_ns}:{st.st_ino}"
    if st.st_size <= SMALL_FILE and os.path.isfile(path):
        ident += ":" + hashlib.sha256(Path(path).read_bytes()).hexdigest()
    return ident


@functools.cache
def code_version() -> str:
    """The package's source and shipped weights, hashed once per process: a changed renderer,
    sampler or restorer invalidates what it made."""
    h = hashlib.sha256()
    for p in sorted(_PACKAGE.rglob("*")):
        if p.suffix in (".py", ".safetensors", ".json") and "data" not in p.relative_to(_PACKAGE).parts[:1]:
            h.update(f"{p.relative_to(_PACKAGE).as_posix()}:{file_identity(p)}".encode())
    return h.hexdigest()[:16]


def inputs_key(manifest, plan_options=None, stage_options=None, device: str = "cpu") -> str:
    """The cache key of one run (16 hex digits)."""
    payload = {
        "manifest": manifest.to_json(),
        "plan_options": asdict(plan_options) if plan_options is not None else None,
        "stage_options": asdict(stage_options) if stage_options is not None else None,
        "device": device,
        "code": code_version(),
        "files": {rel: file_identity(manifest.resolve(rel))
                  for rel in [r for _, r in manifest.asset_refs()] + [r for _, r, _ in manifest.ground_truth_refs()]},
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode()).hexdigest()[:16]
