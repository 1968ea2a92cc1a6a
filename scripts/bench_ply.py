"""Time reading and writing a 1M-splat, SH-degree-3 PLY (the add-on and backend load path).

Prints the measured times and the ratio to plyfile reading the same file in the same run.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from symdrive_core.gaussians import Gaussians
from symdrive_core.io.ply import read_splats, write_splats


def _time(fn, repeat):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--count", type=int, default=1_000_000)
    ap.add_argument("--degree", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    n, k = args.count, (args.degree + 1) ** 2
    g = Gaussians(rng.normal(size=(n, 3)).astype("f4"), rng.normal(size=(n, 4)).astype("f4"),
                  rng.normal(size=(n, 3)).astype("f4"), rng.normal(size=n).astype("f4"),
                  rng.normal(size=(n, k, 3)).astype("f4"))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.ply"
        t_write = _time(lambda: write_splats(path, g), args.repeat)
        t_read = _time(lambda: read_splats(path), args.repeat)
        size_mb = path.stat().st_size / 1e6
        print(f"{n} splats, SH degree {args.degree}, {size_mb:.0f} MB")
        print(f"write_splats  {t_write:7.3f} s")
        print(f"read_splats   {t_read:7.3f} s   (target < 2 s)")
        try:
            from plyfile import PlyData
        except ImportError:
            return
        t_plyfile = _time(lambda: np.array(PlyData.read(str(path))["vertex"].data), args.repeat)
        print(f"plyfile read  {t_plyfile:7.3f} s   (memory-mapped, then copied; raw table only)")
        print(f"ratio read_splats / plyfile = {t_read / t_plyfile:.2f}")


if __name__ == "__main__":
    main()
