"""Insertion benchmark: every insertion method on held-out placements, harmonization time per frame,
fine-tune time, and harmonization quality against sampler steps.

    python scripts/bench_insertion.py --package symdrive_core/data/demo_street \
        --gaussians out/recon/background.ply --steps 5 10 25 50 --out bench_insertion.json

Needs the package's ``ground_truth.insertion`` (Cycles renders of the vehicle truly in the scene)
and the built-in restorer. Rows follow REPORT.md's ``metrics.insertion``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--package", required=True, type=Path)
    p.add_argument("--gaussians", required=True, type=Path, help="reconstruction PLY")
    p.add_argument("--steps", type=int, nargs="*", default=[5, 10, 25, 50], help="sampler steps to sweep")
    p.add_argument("--main-steps", type=int, help="steps for the full run of every method (default: HarmonizeConfig's)")
    p.add_argument("--finetune-iters", type=int, help="colour/opacity fine-tune iterations (default: the config's)")
    p.add_argument("--train-views", type=int, help="training views per placement (default: the config's)")
    p.add_argument("--features-module", help="extractor for the Frechet distance (FILE.py:FN, MODULE:FN, .pt)")
    p.add_argument("--out", type=Path, default=Path("bench_insertion.json"))
    args = p.parse_args(argv)

    from symdrive_core.cli import given
    from symdrive_core.diffusion.models import load_restorer
    from symdrive_core.eval.insertion import evaluate_insertion
    from symdrive_core.insertion.config import HarmonizeConfig, InsertionConfig
    from symdrive_core.insertion.features import load_extractor
    from symdrive_core.insertion.harmonizer import restorer_harmonizer
    from symdrive_core.io.atomic import write_text_atomic
    from symdrive_core.io.ply import read_splats
    from symdrive_core.optim.config import FinetuneConfig
    from symdrive_core.scene import load_manifest

    manifest = load_manifest(args.package)
    background = read_splats(args.gaussians, drop_invalid=True)
    restorer = load_restorer()
    extractor = load_extractor(args.features_module) if args.features_module else None
    result: dict = {"package": str(args.package), "sweep": []}

    details: dict = {}
    t0 = time.perf_counter()
    cfg = InsertionConfig(**given(args, "train_views"),
                          finetune=FinetuneConfig(**given(args, steps="finetune_iters")))
    harmonize = HarmonizeConfig(**given(args, steps="main_steps"))
    result["insertion"] = evaluate_insertion(manifest, background, harmonizer=restorer_harmonizer(restorer, harmonize),
                                             config=cfg, extractor=extractor, details=details)
    result["seconds"] = round(time.perf_counter() - t0, 2)
    result["details"] = details
    for steps in args.steps:  # harmonization only: no training views, no fine-tune
        d: dict = {}
        sweep = restorer_harmonizer(restorer, HarmonizeConfig(steps=steps))
        rows = evaluate_insertion(manifest, background, harmonizer=sweep, config=InsertionConfig(train_views=0),
                                  details=d, progress=False)
        harm = next(r for r in rows if r["method"] == "harmonized")
        secs = d["timings"]["harmonize_seconds"]
        result["sweep"].append({"steps": steps, **{k: harm[k] for k in ("masked_psnr", "masked_ssim", "psnr")},
                                "seconds_per_frame": round(sum(secs) / len(secs), 3)})
        print(json.dumps(result["sweep"][-1]))
    write_text_atomic(args.out, json.dumps(result, indent=1) + "\n")
    print(json.dumps(result["insertion"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
