"""``symdrive reconstruct``: fit background Gaussians (and each recorded vehicle's, in its own frame)
to a scene package's training drive."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from ..optim.config import COARSE_TO_FINE, ReconstructConfig
from . import (
    add_quiet_option,
    angle_deg,
    count_int,
    default_of,
    given,
    loss_weight,
    positive_int,
    seed_int,
    unit_fraction,
)


def resolution_schedule_arg(text: str) -> tuple[float, ...] | None:
    """``--resolution-schedule``: increasing fractions of the iterations, comma-separated; ``full``
    (or nothing) trains at full resolution throughout; ``auto`` (None) lets the image size choose."""
    if text.strip().lower() in ("", "full"):
        return ()
    if text.strip().lower() == "auto":
        return None
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated fractions of the iterations, got {text!r}") from None
    if not all(0.0 < v <= 1.0 for v in values) or list(values) != sorted(set(values)):
        raise argparse.ArgumentTypeError(f"expected increasing fractions in (0, 1], got {text!r}")
    return values


def add_commands(sub) -> None:
    from . import add_external_assets_option

    p = sub.add_parser("reconstruct", help="3DGS reconstruction of a scene package's background (CPU)")
    p.add_argument("package", help="scene package directory or its manifest.json")
    p.add_argument("--iters", type=positive_int, help=f"training iterations (default {default_of(ReconstructConfig, 'iters')})")
    p.add_argument("--out", type=Path, default=None, help="output folder (default PACKAGE/reconstruction)")
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint if present")
    p.add_argument("--sh-degree", type=count_int,
                   help=f"SH degree of the result (default {default_of(ReconstructConfig, 'sh_degree')})")
    p.add_argument("--sh-every", type=positive_int, help="raise the trained SH degree every N iterations "
                   f"(default {default_of(ReconstructConfig, 'sh_every')})")
    p.add_argument("--resolution-schedule", type=resolution_schedule_arg, metavar="F,...",
                   help="coarse to fine: the fractions of the iterations at which the training images' downscale "
                        "halves, e.g. 0.1,0.3 trains at 1/4 resolution until 10 %%, 1/2 until 30 %%, full after; "
                        "'full': full resolution throughout; 'auto' (the default): "
                        f"{','.join(map(str, COARSE_TO_FINE))} for images of at least "
                        f"{default_of(ReconstructConfig, 'coarse_to_fine_pixels')} pixels, full below")
    p.add_argument("--depth-weight", type=loss_weight, help="inverse-depth L1 weight at the depth maps' measured pixels, "
                   f"0 = off (default {default_of(ReconstructConfig, 'sensor_depth_weight')} where the depth is LiDAR's, "
                   "sparse, as `import lidar` writes it; else 0)")
    p.add_argument("--exposure", choices=("off", "camera", "frame"),
                   help="each view's render through a learnt affine colour transform before the loss: one per camera "
                        "but the first ('camera'), one per view ('frame'), or none "
                        f"(default {default_of(ReconstructConfig, 'exposure')})")
    p.add_argument("--sky-skyline", action=argparse.BooleanOptionalAction, default=None,
                   help="in views without depth (SfM-only drives), start the sky dome above the horizon and the "
                        "skyline the point cloud draws in each view; off: only where a dense depth map marks the sky "
                        f"(default {'on' if ReconstructConfig().sky.skyline else 'off'})")
    p.add_argument("--sensor-dome-deg", type=angle_deg, metavar="DEG",
                   help="where the depth is a sensor's (LiDAR), start the sky dome above the horizon and the returns' "
                        "skyline as broad Gaussians of this size (one standard deviation, degrees) that keep their places "
                        "and sizes; 0: no dome there "
                        f"(default {default_of(ReconstructConfig, 'sky.sensor_dome_deg')})")
    p.add_argument("--max-gaussians", type=positive_int,
                   help=f"cap for densification (default {default_of(ReconstructConfig, 'densify.max_gaussians')})")
    p.add_argument("--densify-until", type=unit_fraction, metavar="F",
                   help="stop densifying at this fraction of the iterations "
                        f"(default {default_of(ReconstructConfig, 'densify_until_fraction')})")
    p.add_argument("--importance-prune", type=unit_fraction, metavar="F",
                   help="when densifying stops, remove this fraction of each part's Gaussians, those that paint the "
                        "least of the training views, so that every later step composites fewer; 0: none "
                        f"(default {default_of(ReconstructConfig, 'importance_prune')})")
    p.add_argument("--max-init-points", type=positive_int, help="point-cloud subset to start from "
                   f"(default {default_of(ReconstructConfig, 'max_init_points')})")
    p.add_argument("--seed", type=seed_int,
                   help=f"random seed of the reconstruction (default {default_of(ReconstructConfig, 'seed')})")
    p.add_argument("--static", action="store_true",
                   help="one static scene: do not fit the recorded vehicles (existing actors with a box) in their own "
                        "frames")
    p.add_argument("--refine-poses", action=argparse.BooleanOptionalAction, default=None,
                   help="learn a correction of each recorded vehicle's per-frame pose with its Gaussians, written back "
                        "as its recorded poses (the tracks' boxes kept as tracked_poses); default: the vehicles whose "
                        "boxes came from `symdrive import tracks`")
    p.add_argument("--vehicle-alpha-weight", type=loss_weight, metavar="W",
                   help="cost of each pixel a recorded vehicle covers, so its Gaussians draw only what the background "
                        f"behind it does not (default {default_of(ReconstructConfig, 'vehicle_alpha_weight')}; 0: off)")
    p.add_argument("--driving-view-repeat", type=positive_int, metavar="N",
                   help="views that show a recorded vehicle driving come N times in each pass over the views "
                        f"(default {default_of(ReconstructConfig, 'driving_view_repeat')}; 1: once, as every other view)")
    p.add_argument("--refine-cameras", action=argparse.BooleanOptionalAction, default=None, dest="refine_cameras",
                   help="learn a correction of each frame's camera poses (the rig together) with the Gaussians, "
                        "written back as the cameras' poses (the recording's kept as recorded_camera_to_world) "
                        f"(default enabled: {default_of(ReconstructConfig, 'camera_refine.enabled')})")
    p.add_argument("--lateral", action="store_true", help="also score the result at the lateral ground truth")
    p.add_argument("--no-link", action="store_true",
                   help="do not point the manifest's background.splats (and the recorded vehicles' assets.splats) at "
                        "the result, nor write refined poses into it")
    add_quiet_option(p)
    add_external_assets_option(p)
    p.set_defaults(func=_reconstruct)


def _reconstruct(args) -> int:
    import json

    from ..optim.reconstruct import SHADOW_SUFFIX, reconstruct, with_fitted
    from ..scene import ManifestError, check_files, is_inside, load_manifest

    manifest = load_manifest(args.package, allow_external=args.allow_external_assets)
    check_files(manifest)
    cfg = ReconstructConfig(**given(args, "iters", "sh_degree", "sh_every", "resolution_schedule", "depth_weight",
                                    "max_init_points", "seed", "exposure", "vehicle_alpha_weight", "driving_view_repeat",
                                    "importance_prune", densify_until_fraction="densify_until"))
    cfg.densify = replace(cfg.densify, **given(args, "max_gaussians"))
    cfg.pose_refine = replace(cfg.pose_refine, **given(args, enabled="refine_poses"))
    cfg.camera_refine = replace(cfg.camera_refine, **given(args, enabled="refine_cameras"))
    cfg.sky = replace(cfg.sky, **given(args, "sensor_dome_deg", skyline="sky_skyline"))
    if args.static:
        cfg.decompose = False
    if args.lateral:  # checked before hours of fitting, not after
        from ..scene.ground_truth import require_truth

        require_truth(manifest, "lateral", "reconstruct --lateral needs it; drop --lateral to reconstruct without it")
    out = args.out or manifest.root / "reconstruction"
    if args.out is None and not is_inside(out, manifest.root):  # a link shipped in the package
        raise ManifestError(manifest.path or manifest.root, "'reconstruction' leads out of the package (a link); "
                            "pass --out", "reconstruction")
    result = reconstruct(manifest, out, cfg, resume=args.resume, progress=not args.quiet)
    with_fitted(manifest, result.poses, result.cameras)  # scored, and linked, where the fit placed them
    metrics = result.metrics
    if metrics["heldout_frames"] or args.lateral:
        from ..eval.views import evaluate_heldout, evaluate_lateral
        from ..io.atomic import write_text_atomic

        if metrics["heldout_frames"]:
            metrics["heldout"] = evaluate_heldout(manifest, result.gaussians, metrics["heldout_frames"],
                                                  actors=result.actors, shadows=result.shadows,
                                                  exposure=result.exposure)
        if args.lateral:
            metrics["lateral"] = evaluate_lateral(manifest, result.gaussians)
        write_text_atomic(Path(out) / "metrics.json", json.dumps(metrics, indent=1) + "\n")
    root = manifest.root.resolve()
    ply = (Path(out) / "background.ply").resolve()
    if not args.no_link and ply.is_relative_to(root):
        manifest.background_splats = ply.relative_to(root).as_posix()
        for a in manifest.actors:
            if a.id in result.actors:
                a.splats = (Path(out) / "actors" / f"{a.id}.ply").resolve().relative_to(root).as_posix()
                a.shadow = (Path(out) / "actors" / f"{a.id}{SHADOW_SUFFIX}").resolve().relative_to(root).as_posix() \
                    if a.id in result.shadows else None
        manifest.save()
    summary = {k: metrics[k] for k in ("gaussians", "actors", "cameras", "cameras_left_out", "seconds",
                                       "seconds_per_iteration", "heldout", "lateral")
               if k in metrics and metrics[k] != {}}
    print(json.dumps(summary, indent=1))
    return 0
