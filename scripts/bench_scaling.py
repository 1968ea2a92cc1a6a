"""How the CPU rasterizer's time grows with the Gaussian count and with the pixel count, as log-log
curves with their fitted slopes (PNG and JSON).

    python scripts/bench_scaling.py --out docs/scaling        # docs/scaling.png, docs/scaling.json
    python scripts/bench_scaling.py --quick --out /tmp/scaling

Scenes are ``bench_render.make_scene``'s street-like clouds (SH degree 3; each Gaussian a few
pixels wide whatever the count and resolution, as in a trained scene of that density). Counts
100k to 5M at 1280x720; resolutions 256x144 to 3840x2160 with 1M Gaussians. Each point is the best
of a few runs after a warm-up, forward and forward+backward. A slope of 1 means time proportional
to the count (or to the pixels); the per-pixel cost of a fixed scene falls with resolution only if
Gaussians grow with it, which these scenes do.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from bench_render import make_scene, timeit  # noqa: E402

from symdrive_core.io.atomic import atomic_path  # noqa: E402
from symdrive_core.splat import rasterize  # noqa: E402

COUNTS = (100_000, 300_000, 1_000_000, 3_000_000, 5_000_000)
SIZES = ((256, 144), (640, 360), (1280, 720), (1920, 1080), (3840, 2160))
QUICK_COUNTS = (30_000, 100_000, 300_000)
QUICK_SIZES = ((256, 144), (640, 360), (1280, 720))


def measure(n: int, width: int, height: int, budget_s: float) -> dict:
    ps, viewmat, K = make_scene(n, width, height)

    def forward():
        with torch.no_grad():
            return rasterize(*ps, viewmat, K, width, height)

    def forward_backward():
        leaves = [p.detach().requires_grad_(True) for p in ps]
        rgb, _, _ = rasterize(*leaves, viewmat, K, width, height)
        rgb.sum().backward()

    fwd, (_, _, info) = timeit(forward, budget_s=budget_s)
    both, _ = timeit(forward_backward, budget_s=budget_s)
    row = {"gaussians": n, "width": width, "height": height, "pixels": width * height, "forward_s": fwd,
           "forward_backward_s": both, "tile_gaussian_pairs": int(info["bins"].ids.shape[0])}
    print(f"{n:9d} Gaussians {width:4d}x{height:<4d}  forward {fwd:7.3f} s  forward+backward {both:7.3f} s  "
          f"pairs {row['tile_gaussian_pairs']:,}", flush=True)
    return row


def slope(rows: list[dict], x: str, y: str) -> float:
    """Least-squares slope of log(y) against log(x)."""
    return float(np.polyfit(np.log([r[x] for r in rows]), np.log([r[y] for r in rows]), 1)[0])


def plot(path: Path, by_count: list[dict], by_size: list[dict], slopes: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6))
    for ax, rows, x, label in ((axes[0], by_count, "gaussians", "Gaussians (1280x720)"),
                               (axes[1], by_size, "pixels", "pixels (1M Gaussians)")):
        for y, style in (("forward_s", "o-"), ("forward_backward_s", "s--")):
            key = f"{y[:-2]}_vs_{x}"
            ax.loglog([r[x] for r in rows], [r[y] for r in rows], style, ms=4,
                      label=f"{y[:-2].replace('_', '+')} (slope {slopes[key]:.2f})")
        ax.set_xlabel(label)
        ax.set_ylabel("seconds per frame")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    fig.suptitle(f"CPU rasterizer, {torch.get_num_threads()} threads", fontsize=9)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, required=True, help="path stem: writes STEM.png and STEM.json")
    p.add_argument("--quick", action="store_true", help="three small points per curve (about a minute)")
    p.add_argument("--budget", type=float, default=20.0, help="seconds of repeats per point at most")
    args = p.parse_args(argv)
    counts, sizes = (QUICK_COUNTS, QUICK_SIZES) if args.quick else (COUNTS, SIZES)
    base_w, base_h = sizes[-1] if args.quick else (1280, 720)
    base_n = counts[-1] if args.quick else 1_000_000
    t0 = time.perf_counter()
    by_count = [measure(n, base_w, base_h, args.budget) for n in counts]
    by_size = [measure(base_n, w, h, args.budget) for w, h in sizes]
    slopes = {f"{y[:-2]}_vs_{x}": slope(rows, x, y) for rows, x in ((by_count, "gaussians"), (by_size, "pixels"))
              for y in ("forward_s", "forward_backward_s")}
    for k, v in slopes.items():
        print(f"slope {k}: {v:.2f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    result = {"threads": torch.get_num_threads(), "load_average": os.getloadavg()[0], "by_count": by_count,
              "by_pixels": by_size, "slopes": slopes, "seconds": round(time.perf_counter() - t0, 1)}
    with atomic_path(args.out.with_suffix(".json")) as tmp:
        Path(tmp).write_text(json.dumps(result, indent=1) + "\n")
    plot(args.out.with_suffix(".png"), by_count, by_size, slopes)
    print(f"wrote {args.out.with_suffix('.png')} and {args.out.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
