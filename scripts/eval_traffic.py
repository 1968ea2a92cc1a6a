"""Moving traffic against its Cycles truth: a static and a decomposed reconstruction of the same
drive on held-out frames (image, moving vehicles' pixels, elsewhere), and the package's edits of
recorded vehicles (remove, move, retime) rendered as they are and with what they expose inpainted.

    python scripts/make_world.py --out out/traffic --traffic 5 --frames 40 --offsets --placements 0
    symdrive reconstruct out/traffic --out out/traffic/decomposed
    symdrive reconstruct out/traffic --out out/traffic/static --static --no-link
    python scripts/eval_traffic.py out/traffic --static out/traffic/static \
        --decomposed out/traffic/decomposed --out traffic.json

Needs the package's ``ground_truth.vehicles`` and ``ground_truth.edits`` and the built-in restorer.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def _figure(m, static, decomposed, inpaint, which: int, path: Path) -> None:
    import numpy as np

    from symdrive_core.eval.edits import edited
    from symdrive_core.eval.views import TrafficRenderer
    from symdrive_core.insertion.exposed import inpaint_region
    from symdrive_core.io.images import read_image, write_image
    from symdrive_core.scene.camera import CameraView
    from symdrive_core.scene.ground_truth import edit_truth

    e = [e for e in edit_truth(m) if e.kind == "remove"][which]
    recorded = read_image(m.resolve(m.camera(e.camera).frames[e.frame].image), channels=3)
    static_rgb, _ = TrafficRenderer(static[0], {}).render(m, e.camera, e.frame, recorded=True)
    r = TrafficRenderer(*decomposed)
    decomposed_rgb, was = r.render(m, e.camera, e.frame, recorded=True)
    edit = edited(m, e)
    removed, now = r.render(edit, e.camera, e.frame)
    hole = inpaint_region(edit, CameraView.of_frame(m.camera(e.camera), e.frame), was, now, [e.actor],
                          r.street_depth(edit, e.camera, e.frame))
    if hole is not None and inpaint is not None:
        removed = inpaint(removed, hole)
    row = [recorded, static_rgb, decomposed_rgb, removed, read_image(m.resolve(e.image), channels=3)]
    gap = np.ones((recorded.shape[0], 4, 3), np.float32)
    write_image(path, np.concatenate([x for im in row for x in (im, gap)][:-1], axis=1))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("package", type=Path)
    p.add_argument("--static", required=True, type=Path, help="folder of `symdrive reconstruct --static`")
    p.add_argument("--decomposed", required=True, type=Path, help="folder of `symdrive reconstruct`")
    p.add_argument("--no-inpaint", action="store_true", help="score the edits as rendered only (no diffusion model)")
    p.add_argument("--out", type=Path, default=Path("traffic.json"))
    p.add_argument("--figure", type=Path, help="also write one removal as a row of images: recorded, static, "
                                               "decomposed, car removed, Cycles truth without it")
    p.add_argument("--figure-edit", type=int, default=0, help="which removal of ground_truth.edits (default the first)")
    args = p.parse_args(argv)

    from symdrive_core.eval.edits import evaluate_decomposition, evaluate_edits
    from symdrive_core.io.atomic import write_text_atomic
    from symdrive_core.optim.reconstruct import read_reconstruction
    from symdrive_core.scene import load_manifest

    m = load_manifest(args.package)
    static, decomposed = read_reconstruction(args.static), read_reconstruction(args.decomposed)
    background, actors, shadows = decomposed
    results = {"heldout": {"static": evaluate_decomposition(m, static[0], {}),
                           "decomposed": evaluate_decomposition(m, background, actors, shadows=shadows)}}
    inpaint = None
    if not args.no_inpaint:
        from symdrive_core.diffusion.models import load_restorer
        from symdrive_core.insertion.config import InpaintConfig
        from symdrive_core.insertion.harmonizer import restorer_harmonizer

        inpaint = restorer_harmonizer(load_restorer(), InpaintConfig().harmonize)
    t0 = time.perf_counter()
    results["edits"] = evaluate_edits(m, background, actors, inpaint=inpaint, shadows=shadows)
    results["edits_seconds"] = round(time.perf_counter() - t0, 1)
    write_text_atomic(args.out, json.dumps(results, indent=1) + "\n")
    if args.figure:
        _figure(m, static, decomposed, inpaint, args.figure_edit, args.figure)
    print(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    sys.exit(main())
