"""Tracked boxes that jitter: exact boxes jittered by a known noise, imported as tracks, and the
reconstructions' refined poses and held-out vehicles scored against the truth.

    cp -r symdrive_core/data/traffic_street out/jitter
    python scripts/eval_pose_refine.py jitter out/jitter --out out/jitter.json --translation-m 0.2 --yaw-deg 2
    symdrive import tracks out/jitter out/jitter.json --replace
    symdrive reconstruct symdrive_core/data/traffic_street --out out/exact --no-link
    symdrive reconstruct out/jitter --out out/jittered --no-link --no-refine-poses
    symdrive reconstruct out/jitter --out out/refined --no-link
    python scripts/eval_pose_refine.py score symdrive_core/data/traffic_street out/jitter \
        --exact out/exact --jittered out/jittered --refined out/refined --out pose_refine.json

Scores: the poses each fit places the vehicles at (the tracks' boxes, or the refined poses of
``poses.json``) against the exact boxes (cm, degrees; training and held-out frames apart), and
the held-out frames' PSNR over the moving vehicles' pixels and elsewhere
(:func:`symdrive_core.eval.edits.evaluate_decomposition`), each fit rendered at the poses it placed
its vehicles at.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from symdrive_core.cli import number_at_least_zero


def _jitter(args) -> int:
    import numpy as np

    from symdrive_core.eval.poses import jittered
    from symdrive_core.io.atomic import write_text_atomic
    from symdrive_core.scene import load_manifest

    m = load_manifest(args.package)
    rng = np.random.default_rng(args.seed)
    tracks = []
    for a in m.actors:
        if a.kind != "existing" or a.wlh is None:
            continue
        boxes = jittered([a.recorded_pose(f) for f in range(len(a.poses))], args.translation_m,
                         np.radians(args.yaw_deg), rng)
        w, length, h = (float(v) for v in a.wlh)
        tracks.append({"id": a.id, "w": w, "l": length, "h": h, "boxes": [
            {"frame": f, "centre": [float(v) for v in p.translation], "quaternion": [float(v) for v in p.rotation]}
            for f, p in enumerate(boxes) if p is not None]})
    write_text_atomic(args.out, json.dumps({"frame": "world", "tracks": tracks}, indent=1) + "\n")
    print(f"{args.out}: {len(tracks)} tracks, boxes moved {args.translation_m} m and turned {args.yaw_deg} degrees")
    return 0


def _fit(folder: Path, package):
    """(background, actors, their shadow layers, the package placing the vehicles where this fit
    placed them)."""
    from symdrive_core.optim.reconstruct import as_fitted, read_reconstruction
    from symdrive_core.scene import load_manifest

    return *read_reconstruction(folder), as_fitted(load_manifest(package), folder)


def _score(args) -> int:
    from symdrive_core.eval.edits import evaluate_decomposition
    from symdrive_core.eval.poses import pose_errors
    from symdrive_core.io.atomic import write_text_atomic
    from symdrive_core.scene import load_manifest
    from symdrive_core.scene.ground_truth import split_frames

    truth = load_manifest(args.truth)
    train, heldout = split_frames(truth)
    results = {}
    for name, folder, package in (("exact", args.exact, args.truth), ("jittered", args.jittered, args.package),
                                  ("refined", args.refined, args.package)):
        background, actors, shadows, m = _fit(folder, package)
        row = {"heldout": evaluate_decomposition(m, background, actors, shadows=shadows), "poses": {}}
        for which, frames in (("train", train), ("heldout", heldout)):
            errors = [pose_errors([a.recorded_pose(f) for f in range(len(a.poses))],
                                  [truth.actor(a.id).recorded_pose(f) for f in range(len(a.poses))], frames)
                      for a in m.actors if a.id in actors]
            row["poses"][which] = {k: round(sum(e[k] for e in errors) / len(errors), 3)
                                   for k in ("mean_cm", "mean_deg")}
        results[name] = row
    write_text_atomic(args.out, json.dumps(results, indent=1) + "\n")
    print(json.dumps(results, indent=1))
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(required=True)
    j = sub.add_parser("jitter", help="write the package's recorded vehicles' boxes, jittered, as a tracks file")
    j.add_argument("package", type=Path)
    j.add_argument("--out", type=Path, required=True, help="the tracks JSON to write")
    j.add_argument("--translation-m", type=number_at_least_zero, default=0.2, help="each box moved this far, a random direction")
    j.add_argument("--yaw-deg", type=number_at_least_zero, default=2.0, help="and turned this much, either way")
    j.add_argument("--seed", type=int, default=0)
    j.set_defaults(func=_jitter)
    s = sub.add_parser("score", help="the fits' poses and held-out vehicles against the truth")
    s.add_argument("truth", type=Path, help="the package with the exact boxes")
    s.add_argument("package", type=Path, help="the package the jittered boxes were imported into")
    s.add_argument("--exact", type=Path, required=True, help="reconstruction of the truth package")
    s.add_argument("--jittered", type=Path, required=True, help="reconstruction with the jittered boxes as they are")
    s.add_argument("--refined", type=Path, required=True, help="reconstruction refining the jittered boxes")
    s.add_argument("--out", type=Path, default=Path("pose_refine.json"))
    s.set_defaults(func=_score)
    args = p.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    sys.exit(main())
