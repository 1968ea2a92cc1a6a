"""Pipeline benchmark at full resolution: seconds per frame for each stage and the peak RSS.

    python scripts/bench_pipeline.py                     # 1920x1080, 3M Gaussians, 2 frames
    python scripts/bench_pipeline.py --quick             # 960x540, 1M Gaussians, 1 frame

Builds a self-contained scene package in a temporary folder from the demo street
(``symdrive_core/data/demo_street``): the camera's ``K`` scaled to the new size, the background
reconstruction densified to ``--gaussians`` by splitting (each Gaussian replaced by children drawn
from its own distribution, scales shrunk so the children fill the same volume), two inserted cars
(the demo's hatchback and sedan) in every benchmarked frame, lateral offsets +-1 and +-3 m, the
recorded 256x144 images upsampled to the new size (so the chain is the geometry-guided one, as on
a real package) and no ground truth. Then ``run_scene`` runs the plan (render, restore, harmonize,
finetune; refinement only with ``--refine-iters``) and the script prints seconds per frame for
each stage that ran and the process's peak RSS (``resource.getrusage``), and writes them as JSON
with ``--json``. ``--compare`` first runs the previous default restoration (the guided chain at
d = 0.5 m, the mean of 8 noisy samples) on the same package and prints the ratios of the two.
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import shutil
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from symdrive_core.cli import count_int, positive_int, positive_number

DEMO = Path(__file__).resolve().parents[1] / "symdrive_core" / "data" / "demo_street"
CARS = ("insert_0", "insert_1")
BENCH_FRAMES = (2, 7)  # demo frames whose cameras see both cars ahead


def densify(g, n: int, seed: int = 0):
    """``g`` split to ``n`` Gaussians: each parent gives ``ceil(n / len(g))`` children placed at
    draws from the parent's own Gaussian, scales divided by the cube root of the child count."""
    from symdrive_core.gaussians import Gaussians
    from symdrive_core.rotations import quat_to_matrix

    if n <= len(g):
        return g
    k = math.ceil(n / len(g))
    rng = np.random.default_rng(seed)
    idx = np.repeat(np.arange(len(g)), k)[:n]
    rot = quat_to_matrix(g.unit_quats.astype(np.float64))[idx]
    local = rng.normal(size=(n, 3)) * g.scales[idx].astype(np.float64)
    means = g.means[idx] + np.einsum("nij,nj->ni", rot, local)
    return Gaussians(
        means=means.astype(np.float32),
        quats=g.quats[idx],
        log_scales=(g.log_scales[idx] - np.log(k) / 3.0).astype(np.float32),
        opacity_logits=g.opacity_logits[idx],
        sh=g.sh[idx],
    )


def upsampled(image: np.ndarray, width: int, height: int) -> np.ndarray:
    import torch

    t = torch.from_numpy(image).permute(2, 0, 1)[None]
    t = torch.nn.functional.interpolate(t, size=(height, width), mode="bicubic", align_corners=False)
    return t[0].permute(1, 2, 0).clamp(0, 1).numpy()


def build_package(root: Path, width: int, height: int, gaussians: int, frames: int) -> Path:
    """A self-contained package in ``root``: manifest, the two cars' assets, the densified background."""
    from symdrive_core.io.images import read_image, write_image
    from symdrive_core.io.ply import read_splats, write_splats

    m = json.loads((DEMO / "manifest.json").read_text())
    keep = list(BENCH_FRAMES[:frames])
    cam = m["cameras"][0]
    sx, sy = width / cam["width"], height / cam["height"]
    new_frames = []
    for fi in keep:
        f = dict(cam["frames"][fi])
        K = np.asarray(f["K"], dtype=np.float64)
        K[0] *= sx
        K[1] *= sy
        f["K"] = K.tolist()
        f.pop("depth", None)
        image = read_image(DEMO / f["image"], channels=3)
        f["image"] = f"images/{fi:06d}.png"
        write_image(root / f["image"], upsampled(image, width, height))
        new_frames.append(f)
    cam.update(width=width, height=height, frames=new_frames)
    m["frames"] = [{"index": i, "timestamp": m["frames"][fi]["timestamp"]} for i, fi in enumerate(keep)]
    actors = []
    for a in m["actors"]:
        if a["id"] not in CARS:
            continue
        pose = next(p for p in a["poses"] if p is not None)
        a["poses"] = [pose] * len(keep)
        for key, rel in a["assets"].items():
            dst = root / rel
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(DEMO / rel, dst)
        actors.append(a)
    m["actors"] = actors
    m["masks"] = {"entries": [], "id_maps": []}
    m["ground_truth"] = {}
    m["effects"]["lateral_offsets"] = [-3.0, -1.0, 1.0, 3.0]
    m["name"] = f"bench-{width}x{height}"
    m["output"] = "output"
    bg = densify(read_splats(DEMO / m["background"]["splats"], drop_invalid=True), gaussians)
    write_splats(root / "background.ply", bg)
    shutil.copy2(DEMO / m["background"]["points"], root / "points.ply")
    m["background"] = {"splats": "background.ply", "points": "points.ply"}
    (root / "manifest.json").write_text(json.dumps(m, indent=1))
    return root


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="960x540, 1M Gaussians, 1 frame")
    p.add_argument("--width", type=positive_int)
    p.add_argument("--height", type=positive_int)
    p.add_argument("--gaussians", type=positive_int, help="background Gaussians after splitting (default 3000000)")
    p.add_argument("--frames", type=int, choices=(1, 2), help="frames to run (default 2, 1 with --quick)")
    p.add_argument("--max-memory", type=positive_number, metavar="GiB",
                   help="memory for one restorer evaluation (default: the pipeline's)")
    p.add_argument("--samples", type=positive_int, help="restoration samples per view (default: the pipeline's)")
    p.add_argument("--finetune-iters", type=count_int, default=100)
    p.add_argument("--refine-iters", type=count_int, default=0, help="3DGS refinement iterations (0: not run)")
    p.add_argument("--keep", type=Path, help="build the package here and keep it (default: a temporary folder)")
    p.add_argument("--json", type=Path, help="also write the results here")
    p.add_argument("--compare", action="store_true",
                   help="also run the previous default restoration (guided d = 0.5 m, mean of 8 samples) and "
                        "print the ratios")
    p.add_argument("--device", default="cpu",
                   help="torch device of rendering and the restorer (cpu, cuda, cuda:N); the fine-tune runs on "
                        "the CPU kernels")
    p.add_argument("--quiet", action="store_true")
    args = p.parse_args(argv)
    width = args.width or (960 if args.quick else 1920)
    height = args.height or (540 if args.quick else 1080)
    gaussians = args.gaussians or (1_000_000 if args.quick else 3_000_000)
    frames = args.frames or (1 if args.quick else 2)

    from symdrive_core.insertion.config import InsertionConfig
    from symdrive_core.optim.config import FinetuneConfig
    from symdrive_core.pipeline.stages import StageOptions

    opts = StageOptions(insertion=InsertionConfig(finetune=FinetuneConfig(steps=args.finetune_iters)))
    opts.refine = replace(opts.refine, iters=max(args.refine_iters, 1))
    sampler = {"max_memory_gib": args.max_memory, "samples": args.samples}
    opts.sampler = replace(opts.sampler, **{k: v for k, v in sampler.items() if v})
    runs = {"default": opts}
    if args.compare:
        runs["previous"] = replace(opts, guided_ar_step=0.5, sampler=replace(opts.sampler, samples=8, noise_free=False))

    tmp = None
    if args.keep:
        root = args.keep
        root.mkdir(parents=True, exist_ok=True)
    else:
        tmp = tempfile.TemporaryDirectory(prefix="symdrive-bench-")
        root = Path(tmp.name)
    try:
        t0 = time.perf_counter()
        build_package(root / "package", width, height, gaussians, frames)
        build_s = time.perf_counter() - t0
        results = {name: run_once(root, name, o, args, frames) for name, o in runs.items()}
    finally:
        if tmp is not None:
            tmp.cleanup()
    print(f"{width}x{height}, {gaussians:,} Gaussians, {frames} frame(s), {args.device}, max memory "
          f"{opts.sampler.max_memory_gib} GiB, package built in {build_s:.1f} s")
    for name, r in results.items():
        print(f"{name} ({r['method']}, {r['sampler']}):")
        for stage, sec in r["seconds_per_frame"].items():
            print(f"  {stage:<10} {sec:8.2f} s/frame")
        gpu = f", peak GPU memory {r['peak_gpu_gib']} GiB" if "peak_gpu_gib" in r else ""
        print(f"  frame      {r['frame_seconds']:8.2f} s, total run {r['run_seconds']:.1f} s, "
              f"peak RSS {r['peak_rss_gib']} GiB{gpu}")
    if args.compare:
        new, old = results["default"], results["previous"]
        ratios = {"restore": old["seconds_per_frame"]["restore"] / new["seconds_per_frame"]["restore"],
                  "frame": old["frame_seconds"] / new["frame_seconds"]}
        print("previous / default: " + ", ".join(f"{k} {v:.2f}x" for k, v in ratios.items()))
        results["ratios"] = {k: round(v, 2) for k, v in ratios.items()}
    if args.json:
        args.json.write_text(json.dumps({"width": width, "height": height, "gaussians": gaussians, "frames": frames,
                                         "device": args.device,
                                         "max_memory_gib": opts.sampler.max_memory_gib,
                                         "build_seconds": round(build_s, 1), **results}, indent=1) + "\n")
    return 0


PER_FRAME = ("render", "restore", "harmonize", "finetune")  # refinement and adaptation are per drive


def run_once(root: Path, name: str, opts, args, frames: int) -> dict:
    """One ``run_scene`` of the package with ``opts`` into its own folder. The restorer's
    adaptation to the drive is off: it is paid once per drive, not per frame. The peak RSS is the
    process's so far (the runs go in turn, the default first)."""
    import torch

    from symdrive_core.pipeline.plan import PlanOptions
    from symdrive_core.pipeline.run import run_scene

    cuda = args.device.startswith("cuda")
    if cuda:
        torch.cuda.reset_peak_memory_stats(args.device)
    t0 = time.perf_counter()
    report = run_scene(root / "package", root / f"out-{name}", options=PlanOptions(refine=args.refine_iters > 0,
                                                                                   adapt=False),
                       device=args.device, progress=not args.quiet, stage_options=opts)
    total = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # Linux: kilobytes
    gpu = {"peak_gpu_gib": round(torch.cuda.max_memory_allocated(args.device) / 2**30, 2)} if cuda else {}
    ran = [s for s in report["stages"] if s.get("ran") and "seconds" in s]
    stages = {s["name"]: round(s["seconds"] / frames, 2) for s in ran}
    restore = next((s for s in ran if s["name"] == "restore"), {})
    return {"method": restore.get("method"), "sampler": "noise-free" if opts.sampler.noise_free else
            f"mean of {opts.sampler.samples}", "run_seconds": round(total, 1), "seconds_per_frame": stages,
            "frame_seconds": round(sum(v for k, v in stages.items() if k in PER_FRAME), 2),
            "peak_rss_gib": round(peak / 2**30, 2), **gpu}


if __name__ == "__main__":
    sys.exit(main())
