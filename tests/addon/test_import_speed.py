"""1M splats (SH degree 3) import in under 3 s (the measured figure is in bench_import_splats.py)."""

import time

import numpy as np
import pytest

from symdrive_core.gaussians import Gaussians
from symdrive_core.io.ply import write_splats

pytestmark = [pytest.mark.blender, pytest.mark.slow]


def test_million_splats_import_under_three_seconds(blender, tmp_path):
    rng = np.random.default_rng(0)
    n = 1_000_000
    g = Gaussians(
        rng.normal(size=(n, 3)).astype("f4"),
        rng.normal(size=(n, 4)).astype("f4"),
        (rng.normal(size=(n, 3)) - 4).astype("f4"),
        rng.normal(size=n).astype("f4"),
        rng.normal(size=(n, 16, 3)).astype("f4"),
    )
    path = tmp_path / "million.ply"
    write_splats(path, g)
    del g
    t0 = time.perf_counter()
    assert blender.ops.symdrive.import_splats(filepath=str(path), max_points=0) == {"FINISHED"}
    elapsed = time.perf_counter() - t0
    assert len(blender.context.active_object.data.vertices) == n
    assert elapsed < 3.0, f"import took {elapsed:.2f} s"
