"""Time File > Import > 3DGS Splats on a 1M-splat SH-degree-3 PLY (target: under 3 s).

    python tests/addon/bench_import_splats.py [--count 1000000] [--repeat 3]

Prints the operator time (read + hash + mesh + attributes + display modifier), the first
evaluation of the Geometry Nodes display, and the size of a saved .blend next to the PLY's.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from symdrive_core.gaussians import Gaussians
from symdrive_core.io.ply import write_splats


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    import bpy

    import blender_addon

    rng = np.random.default_rng(0)
    n = args.count
    g = Gaussians(
        rng.normal(size=(n, 3)).astype("f4"),
        rng.normal(size=(n, 4)).astype("f4"),
        (rng.normal(size=(n, 3)) - 4).astype("f4"),
        rng.normal(size=n).astype("f4"),
        rng.normal(size=(n, 16, 3)).astype("f4"),
    )
    with tempfile.TemporaryDirectory() as tmp:
        ply = Path(tmp) / "cloud.ply"
        write_splats(ply, g)
        times, evals = [], []
        bpy.ops.wm.read_factory_settings(use_empty=True)
        blender_addon.register()
        try:
            for _ in range(args.repeat):
                bpy.ops.wm.read_factory_settings(use_empty=True)
                t0 = time.perf_counter()
                bpy.ops.symdrive.import_splats(filepath=str(ply), max_points=0)
                times.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                obj = bpy.context.active_object.evaluated_get(bpy.context.evaluated_depsgraph_get())
                geometry = obj.evaluated_geometry()
                shown = len(geometry.pointcloud.points)
                evals.append(time.perf_counter() - t0)
            blend = Path(tmp) / "scene.blend"
            bpy.ops.wm.save_as_mainfile(filepath=str(blend), compress=False)
            print(f"{n} splats, SH degree 3, PLY {ply.stat().st_size / 1e6:.0f} MB")
            print(f"import operator   {statistics.median(times):6.2f} s  (median of {args.repeat}; < 3 s)")
            print(
                f"display eval      {statistics.median(evals):6.2f} s  ({shown} points from mesh to points)"
            )
            print(f".blend size       {blend.stat().st_size / 1e6:6.0f} MB  (no SH payload stored)")
        finally:
            blender_addon.unregister()


if __name__ == "__main__":
    main()
