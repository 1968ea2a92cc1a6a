"""Held-out PSNR (and SSIM) against training seconds for a package's reconstruction, the default
schedule and the others of ``symdrive_core.bench.reconstruction.SCHEDULES`` fitted side by side in
one process: prints how long each takes to reach the held-out PSNR the default ends at, and writes
``curves.csv``, ``summary.json`` and ``curves.png`` to ``--out``.

    python scripts/bench_reconstruct.py symdrive_core/data/demo_street --iters 3000 --every 100 --out DIR
"""

from __future__ import annotations

import argparse
import subprocess
from pathlib import Path

from symdrive_core.bench.reconstruction import (
    SCHEDULES,
    curves,
    default_name,
    format_summary,
    schedule_configs,
    summary,
    training_pixels,
    write_outputs,
)
from symdrive_core.cli import positive_int
from symdrive_core.scene import load_manifest


def commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              cwd=Path(__file__).parent, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("package", help="scene package directory or its manifest.json (with held-out frames)")
    ap.add_argument("--iters", type=positive_int, default=None, help="iterations of every schedule (default: the config's)")
    ap.add_argument("--every", type=positive_int, default=100, help="score the held-out frames every this many iterations")
    ap.add_argument("--only", nargs="+", choices=list(SCHEDULES), help="these schedules (default: all)")
    ap.add_argument("--out", type=Path, default=Path("out/bench_reconstruct"))
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args()

    measured_at = commit()  # the code that runs, before anything else lands
    manifest = load_manifest(args.package)
    chosen = {n: SCHEDULES[n] for n in args.only} if args.only else None
    configs = schedule_configs(args.iters, chosen)
    rows = curves(manifest, configs, args.every, progress=not args.quiet)
    s = summary(rows, default_name(configs, training_pixels(manifest)))
    s["package"], s["commit"] = str(args.package), measured_at
    print(format_summary(s))
    paths = write_outputs(rows, s, configs, args.out, f"{manifest.name}, commit {s['commit']}")
    print("wrote", ", ".join(str(p) for p in paths.values()))


if __name__ == "__main__":
    main()
