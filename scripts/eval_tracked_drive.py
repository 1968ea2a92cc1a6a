"""A real tracked drive's fits scored on its moving vehicles: held-out PSNR over the pixels the
labels' own 2D boxes give the vehicles that drive, and elsewhere.

    symdrive import kitti-raw 2011_09_26/2011_09_26_drive_0009_sync --out drive --heldout-every 5 --copy-images
    symdrive import tracks drive label_02/0001.txt --calib calib/0001.txt
    symdrive reconstruct drive --out fits/static --no-link --static
    symdrive reconstruct drive --out fits/boxes --no-link --no-refine-poses
    symdrive reconstruct drive --out fits/refined --no-link
    python scripts/eval_tracked_drive.py drive label_02/0001.txt \\
        --fit static=fits/static --fit boxes=fits/boxes --fit refined=fits/refined --out tracked.json

A real drive has no vehicle masks; KITTI's tracking labels draw each object's 2D box in the
image by hand, apart from its 3D box, so they mark the vehicles' pixels without the fits' help
(``label_boxes``, in the package's first camera, the one the labels were drawn in). Every camera
is also scored where the labels' 3D boxes project (``boxes``: each box's bounding rectangle in the
image, at the recorded pose the package holds, never a fit's), so a rig's other cameras add their
held-out frames; ``boxes_pooled`` averages the held-out frames of all cameras.
A vehicle drives when its box's centre moves more than ``--moving-m`` in the package's world
over its frames (the parked cars' boxes drift with the labels' and the ego poses' jitter). Each
fit is rendered with the vehicles where it placed them (its refined poses, where it has them)
by :func:`symdrive_core.eval.edits.evaluate_decomposition`; a static fit has no vehicles.
``--training-frames`` scores the frames the fits learnt from instead.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def moving_tracks(manifest, moving_m: float) -> list[str]:
    """Recorded vehicles whose box centre moves more than ``moving_m`` metres over their frames."""
    from symdrive_core.scene.poses import travels

    return [a.id for a in manifest.actors if a.kind == "existing" and a.wlh is not None
            and travels([a.recorded_pose(f) for f in range(len(a.poses))], moving_m)]


def label_masks(labels: Path, ids: list[str], shape: tuple[int, int], label_size: tuple[int, int],
                frame_offset: int = 0) -> dict:
    """Frame -> boolean image: the labels' 2D boxes (KITTI pixels of an image ``label_size`` =
    (width, height)) of the tracks ``ids`` (named as ``import tracks`` names them), scaled to
    ``shape``."""
    import numpy as np

    from symdrive_core.importers.tracks import read_kitti_label_boxes

    h, w = shape
    sx, sy = w / label_size[0], h / label_size[1]
    masks: dict[int, np.ndarray] = {}
    for track, boxes in read_kitti_label_boxes(labels).items():
        if track not in ids:
            continue
        for frame, (x1, y1, x2, y2) in boxes.items():
            mask = masks.setdefault(frame - frame_offset, np.zeros((h, w), bool))
            # KITTI's pixel i covers [i - 0.5, i + 0.5]: the box's pixels are those whose centres it holds
            mask[max(0, round(sy * (y1 + 0.5) - 0.5)):round(sy * (y2 + 0.5) + 0.5),
                 max(0, round(sx * (x1 + 0.5) - 0.5)):round(sx * (x2 + 0.5) + 0.5)] = True
    return masks


def projected_box_masks(manifest, ids: list[str], camera: str) -> dict:
    """Frame -> boolean image of ``camera``: the bounding rectangles of the tracks ``ids``' 3D boxes
    at their recorded poses, where a box lies wholly in front of the camera and reaches the image."""
    import numpy as np

    from symdrive_core import conventions
    from symdrive_core.scene.visibility import box_corners_world, vehicle_local_box

    cam = manifest.camera(camera)
    masks: dict[int, np.ndarray] = {}
    for a in manifest.actors:
        if a.id not in ids:
            continue
        lo, hi = vehicle_local_box(a.wlh)
        for f, frame in enumerate(cam.frames):
            if (pose := a.recorded_pose(f)) is None:
                continue
            uv, z = conventions.project_points(box_corners_world(lo, hi, pose.R, pose.translation),
                                               frame.world_to_camera, frame.K)
            if np.any(z <= conventions.NEAR_PLANE):
                continue
            # pixel i covers [i - 0.5, i + 0.5]: the rectangle's pixels are those whose centres it holds
            (x0, y0), (x1, y1) = np.ceil(uv.min(0)).astype(int), np.floor(uv.max(0)).astype(int)
            x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, cam.width - 1), min(y1, cam.height - 1)
            if x0 <= x1 and y0 <= y1:
                masks.setdefault(f, np.zeros((cam.height, cam.width), bool))[y0:y1 + 1, x0:x1 + 1] = True
    return masks


def pooled(rows: list[dict]) -> dict:
    """Scores of several cameras as one: each mean weighted by its camera's frame count (a camera
    without a score for a key left out of that key)."""
    out = {"frames": sum(r["frames"] for r in rows)}
    for key in ("psnr_image", "psnr_vehicles", "psnr_elsewhere"):
        scored = [(r[key], r["frames"]) for r in rows if r.get(key) is not None and r["frames"]]
        n = sum(w for _, w in scored)
        out[key] = round(sum(v * w for v, w in scored) / n, 3) if n else None
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("package", type=Path, help="the drive's package, its tracks imported")
    p.add_argument("labels", type=Path, help="the KITTI tracking label file the tracks came from")
    p.add_argument("--fit", action="append", required=True, metavar="NAME=DIR",
                   help="a reconstruction folder, named; repeat for each fit")
    p.add_argument("--moving-m", type=float, default=2.0, help="a vehicle drives if its box moves this far")
    p.add_argument("--label-size", type=int, nargs=2, default=(1242, 375), metavar=("W", "H"),
                   help="the size of the images the labels were drawn on")
    p.add_argument("--frame-offset", type=int, default=0, help="the label frame of the package's frame 0")
    p.add_argument("--training-frames", action="store_true",
                   help="score the training frames instead: a fit that scores no higher there underfits, "
                        "one that does fails to carry to the held-out frames")
    p.add_argument("--out", type=Path, default=Path("tracked.json"))
    args = p.parse_args(argv)

    from symdrive_core.eval.edits import evaluate_decomposition
    from symdrive_core.io.atomic import write_text_atomic
    from symdrive_core.optim.reconstruct import as_fitted, read_reconstruction
    from symdrive_core.scene import load_manifest
    from symdrive_core.scene.ground_truth import split_frames

    manifest = load_manifest(args.package)
    frames = split_frames(manifest)[0 if args.training_frames else 1]
    cam = manifest.cameras[0]
    ids = moving_tracks(manifest, args.moving_m)
    masks = label_masks(args.labels, ids, (cam.height, cam.width), tuple(args.label_size), args.frame_offset)
    boxes = {c.name: projected_box_masks(manifest, ids, c.name) for c in manifest.cameras}
    results = {"moving": ids}
    for spec in args.fit:
        name, _, folder = spec.partition("=")
        background, actors, shadows = read_reconstruction(Path(folder))
        m = as_fitted(load_manifest(args.package), Path(folder))
        by_camera = {c: evaluate_decomposition(m, background, actors, frames, shadows=shadows, masks=boxes[c], camera=c)
                     for c in boxes}
        results[name] = {"label_boxes": evaluate_decomposition(m, background, actors, frames, shadows=shadows,
                                                               masks=masks),
                         "boxes": by_camera, "boxes_pooled": pooled(list(by_camera.values()))}
        print(name, json.dumps(results[name]), flush=True)
    write_text_atomic(args.out, json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    sys.exit(main())
