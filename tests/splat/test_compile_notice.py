"""A first compile of the CPU kernels says so on stderr; a second process loads them from the cache."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
NOTICE = "symdrive_core: compiling the CPU kernels"


def first_kernel_call(cache_dir: Path) -> str:
    """stderr of a fresh process that calls one small kernel with numba's cache in ``cache_dir``."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir), "PYTHONPATH": str(REPO)}
    code = "from symdrive_core.splat import kernels; print(kernels.sigma_limit(0.5, 0.01))"
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True,
                          cwd=REPO)
    assert float(done.stdout) > 0.0
    return done.stderr


def test_first_compile_is_announced_once_and_cached(tmp_path):
    first = first_kernel_call(tmp_path)
    assert first.count(NOTICE) == 1
    assert f"cached in {tmp_path}" in first
    assert NOTICE not in first_kernel_call(tmp_path)
