"""Write the exact lane-marking masks of an existing built-in-world package (``gt/lanes/``).

Rebuilds the package's street from its ``ground_truth.generator`` settings (seed, overcast,
frames, spacing, size), checks that the rebuilt cameras are the package's, renders the marking
coverage (``world.lanes``) at every recorded camera and every lateral ground-truth camera, and
adds ``ground_truth.lanes`` to ``manifest.json``. Nothing else in the package changes.
``make_world.py`` writes the same masks for a package it generates.

    python scripts/make_lane_masks.py symdrive_core/data/demo_street
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # world/
sys.path.insert(1, str(Path(__file__).resolve().parents[1]))  # this checkout's symdrive_core


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("package", type=Path, help="a package written by make_world.py")
    args = p.parse_args(argv)
    from symdrive_core.errors import InputError

    try:
        return _write(args.package)
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


def _write(root: Path) -> int:
    import bpy
    import numpy as np
    from tqdm import tqdm
    from world import drive, lanes, render
    from world.package import lateral_dir
    from world.street import build_street

    from symdrive_core import conventions
    from symdrive_core.errors import InputError
    from symdrive_core.io.atomic import write_text_atomic
    from symdrive_core.io.images import write_mask
    from symdrive_core.scene import load_manifest

    manifest = load_manifest(root)
    gt = manifest.ground_truth or {}
    gen = gt.get("generator")
    if not gen or gen.get("script") != "scripts/make_world.py":
        raise InputError(manifest.path, "not written by scripts/make_world.py", "ground_truth.generator")
    cam = manifest.camera(gt.get("camera", manifest.cameras[0].name))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    street = build_street(gen["seed"], gen["overcast"], (gen["frames"] - 1) * gen["spacing_m"],
                          gen.get("material_jitter", 0.0))
    render.setup_cycles(gen["width"], gen["height"], lanes.SAMPLES, gen["seed"])
    cam_obj = render.make_camera(gen.get("lens_mm", render.LENS_MM))
    poses = drive.drive(street, gen["frames"], gen["spacing_m"], height=gen.get("camera_height_m", drive.CAMERA_HEIGHT),
                        pitch_deg=gen.get("pitch_deg", drive.PITCH_DEG))
    for i, (pose, cf) in enumerate(zip(poses, cam.frames, strict=True)):
        if not (np.allclose(pose, cf.camera_to_world, atol=1e-6) and np.allclose(render.camera_K(cam_obj), cf.K)):
            raise InputError(manifest.path, "the rebuilt street's camera differs from the package's",
                             f"cameras[{cam.name}].frames[{i}]")
    jobs = [(i, cf.camera_to_world, lanes.recorded_path(i), None) for i, cf in enumerate(cam.frames)]
    for e in gt.get("lateral", []):
        off = float(e["offset_m"])
        jobs += [(int(k), conventions.lateral_shift(cam.frames[int(k)].camera_to_world, off),
                  lanes.lateral_path(lateral_dir(off), int(k)), off) for k in e["frames"]]
    masks = {rel: lanes.lane_mask(cam_obj, c2w) for _, c2w, rel, _ in tqdm(jobs, desc="lane masks", unit="render")}
    for rel, mask in masks.items():  # every render done before anything is written
        write_mask(root / rel, mask)
    recorded = {i: rel for i, _, rel, off in jobs if off is None}
    lateral: dict[float, dict[int, str]] = {}
    for i, _, rel, off in jobs:
        if off is not None:
            lateral.setdefault(off, {})[i] = rel
    data = json.loads(manifest.path.read_text(encoding="utf-8"))
    data["ground_truth"]["lanes"] = lanes.ground_truth_block(cam.name, recorded, lateral)
    write_text_atomic(manifest.path, json.dumps(data, indent=1) + "\n")
    print(f"wrote {len(masks)} lane masks under {root / 'gt/lanes'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
