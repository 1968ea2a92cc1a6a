"""Generate the built-in street world: a procedural street rendered by Cycles, as a scene package.

Run with a Python that has the ``bpy`` wheel (the project venv does):

    python scripts/make_world.py --out out/street --seed 0 [--overcast] [--frames 30] [--traffic 5]

The package holds the training drive (images, z-depth, OpenCV cameras), the same frames
shifted sideways by +/-0.5 .. 3 m, held-out vehicle insertions (with / without / mask /
shadow mask), a coloured point cloud of the scene surfaces, and three vehicle assets in the
3DRealCar layout. With ``--traffic N``, N vehicles drive in both directions while the ego
records (``world.traffic``): they are existing actors with their exact poses, each drive frame
has a mask of their visible pixels, and each held-out frame where one shows enough is rendered
again with it removed, moved one lane across and 0.5 s later. ``ground_truth`` in
``manifest.json`` indexes all of it (see ``symdrive_core.scene.ground_truth``). Same seed and
settings give the same scene and cameras; ``--traffic 0`` is the street without traffic.
With ``--parked-existing`` the parked cars in view of the drive are existing actors too
(``world.parked``), and each held-out frame is rendered again without its most visible one.
``--camera-height``, ``--pitch``, ``--lens-mm``, ``--material-jitter`` and the sensor's
``--noise``, ``--blur`` and ``--exposure-jitter`` (``world.sensor``) vary what another drive varies,
for a family of streets; their defaults are the built-in street.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # world/
sys.path.insert(1, str(Path(__file__).resolve().parents[1]))  # this checkout's symdrive_core


LATERAL_OFFSETS = (-3.0, -2.0, -1.5, -1.0, -0.5, 0.5, 1.0, 1.5, 2.0, 3.0)


def parse_args(argv=None):
    import bpy  # noqa: F401  (first: the world modules import bmesh, which comes with it)
    from world import drive, render

    from symdrive_core.cli import count_int, number_at_least_zero, positive_int, positive_number, seed_int

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True, type=Path,
                   help="package directory to write (a package there is replaced atomically; other files refuse it)")
    p.add_argument("--seed", type=seed_int, default=0)
    p.add_argument("--width", type=positive_int, default=256)
    p.add_argument("--height", type=positive_int, default=144)
    p.add_argument("--frames", type=positive_int, default=30, help="training-drive frames")
    p.add_argument("--spacing", type=positive_number, default=1.0, help="metres between training frames")
    p.add_argument("--samples", type=positive_int, default=32, help="Cycles samples per pixel (denoised with OIDN)")
    p.add_argument("--overcast", action="store_true", help="no sun: flat grey sky, no hard shadows")
    p.add_argument("--lateral-every", type=positive_int, default=2, help="render lateral offsets at every k-th frame")
    p.add_argument("--offsets", type=float, nargs="*", default=list(LATERAL_OFFSETS))
    p.add_argument("--holdout-every", type=count_int, default=5,
                   help="every k-th frame is held out of training (0: none)")
    p.add_argument("--placements", type=count_int, default=3, help="held-out vehicle insertions")
    p.add_argument("--points", type=positive_int, default=60000, help="points in the initial point cloud (at most)")
    p.add_argument("--asset-splats", type=positive_int, default=12000, help="splats per vehicle asset")
    p.add_argument("--traffic", type=count_int, default=0,
                   help="moving vehicles driving while the ego records (existing actors, with exact truth for "
                        "removing, moving and retiming them on held-out frames)")
    p.add_argument("--edit-pixels", type=count_int, default=200,
                   help="least visible pixels of a traffic car for a held-out frame's edit truth")
    p.add_argument("--parked-existing", action="store_true",
                   help="the parked cars in view of the drive become existing actors too (ids parked_<k>, the same "
                        "pose in every frame, no assets), and each held-out frame gets a remove edit of its most "
                        "visible parked car (at least --edit-pixels); gt/vehicles stays the moving traffic only")
    p.add_argument("--save-blend", action="store_true", help="also save world.blend in the package")
    # what another drive varies: the camera, the ground's materials, the sensor (a family of streets)
    p.add_argument("--camera-height", type=positive_number, default=drive.CAMERA_HEIGHT, help="metres above the road")
    p.add_argument("--pitch", type=float, default=drive.PITCH_DEG, help="degrees the camera looks down")
    p.add_argument("--lens-mm", type=positive_number, default=render.LENS_MM, help="focal length on a 36 mm sensor")
    p.add_argument("--material-jitter", type=number_at_least_zero, default=0.0,
                   help="each ground material's colours scaled by a seeded 1 +/- this per channel")
    p.add_argument("--noise", type=number_at_least_zero, default=0.0, help="sensor noise: standard deviation in [0, 1] units")
    p.add_argument("--blur", type=number_at_least_zero, default=0.0, help="Gaussian blur of every recorded image, sigma in pixels")
    p.add_argument("--exposure-jitter", type=number_at_least_zero, default=0.0,
                   help="each frame's exposure scaled by exp(u), u uniform in +/- this")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv if argv is not None else _argv_after_dashes())
    from tqdm import tqdm
    from world.package import PackageWriter

    from symdrive_core.io.atomic import atomic_directory

    if args.out.exists() and not (args.out.is_dir() and (not any(args.out.iterdir())
                                                          or (args.out / "manifest.json").is_file())):
        print(f"make_world.py: error: {args.out}: --out is no new or empty folder and no scene package: it would be "
              "replaced whole; choose a new or empty folder", file=sys.stderr)
        return 2
    t0 = time.time()
    with atomic_directory(args.out) as tmp:
        writer = PackageWriter(tmp, args)
        jobs = writer.plan()
        with tqdm(total=len(jobs), desc="cycles", unit="render") as bar:
            for job in jobs:
                job()
                bar.update()
        writer.finish()
    print(f"wrote {args.out} in {time.time() - t0:.0f} s "
          f"({writer.seconds_per_render:.2f} s per Cycles render, {writer.renders} renders)")
    return 0


def _argv_after_dashes():
    """``blender --background --python make_world.py -- ARGS`` passes ARGS after ``--``."""
    return sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]


if __name__ == "__main__":
    sys.exit(main())
