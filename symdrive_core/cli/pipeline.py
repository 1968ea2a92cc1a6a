"""Pipeline subcommands: ``plan`` (what a scene needs, without running it) ``run``, ``batch`` and
``render`` (a quick look at one camera)."""

from __future__ import annotations

import argparse
import math

from ..diffusion.adapt import AdaptConfig
from ..pipeline.batch import run_batch
from ..pipeline.stages import StageOptions
from . import (
    add_frames_option,
    add_json_option,
    add_offsets_option,
    add_quiet_option,
    default_of,
    given,
    names_arg,
    positive_int,
    positive_number,
)


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"expected a number of seconds >= 0, got {text!r}")
    return value


FORCE_HELP = "run in a folder that holds files no symdrive run wrote (they are left alone, never deleted)"


def add_commands(sub) -> None:
    from . import add_external_assets_option, device_arg

    p = sub.add_parser("plan", help="print the stages a scene package needs, and why, without running them")
    p.add_argument("package", help="scene package directory or its manifest.json")
    p.add_argument("--no-refine", action="store_true", help="plan without 3DGS refinement")
    p.add_argument("--no-adapt", action="store_true", help="plan without adapting the restorer to the drive")
    _add_window_options(p)
    add_json_option(p, "the plan")
    add_external_assets_option(p)
    p.set_defaults(func=_plan)

    p = sub.add_parser("run", help="run a scene package's plan: render, restore, harmonize, ... (resumable)")
    p.add_argument("package", help="scene package directory or its manifest.json")
    p.add_argument("--out", help="output directory (default: the manifest's `output`, inside the package)")
    p.add_argument("--device", default="cpu", type=device_arg, help="torch device (cpu, cuda, cuda:N)")
    p.add_argument("--no-refine", action="store_true", help="run without 3DGS refinement")
    _add_window_options(p)
    p.add_argument("--no-adapt", action="store_true",
                   help="restore with the shipped restorer even on a drive its weights were not trained on")
    p.add_argument("--adapt-iters", type=positive_int,
                   help=f"training iterations of the restorer's adaptation (default {default_of(AdaptConfig, 'iters')})")
    p.add_argument("--adapt-seconds", type=_seconds, metavar="S",
                   help="time budget of the adaptation, its pairs included "
                        f"(default {default_of(AdaptConfig, 'max_seconds')})")
    p.add_argument("--no-sensor-pairs", dest="sensor_pairs", action="store_const", const=False,
                   help="adapt on the synthetic pairs alone, even where a rig's second camera recorded the "
                        "training frames (lateral truth imported with --lateral-truth)")
    add_quiet_option(p)
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--max-memory", type=positive_number, metavar="GiB",
                   help="memory for one restorer evaluation; larger images run on tiles "
                        f"(default {default_of(StageOptions, 'sampler.max_memory_gib')})")
    add_external_assets_option(p)
    p.set_defaults(func=_run)

    p = sub.add_parser("batch", help="run many scene packages, in-process or on a Ray cluster")
    p.add_argument("packages", nargs="+", help="scene package directories or manifest.json files")
    p.add_argument("--out", required=True, help="output root; each scene gets a subdirectory")
    p.add_argument("--executor", choices=["local", "ray"], default="local",
                   help="local: the scenes one after another in this process; ray: tasks on a Ray cluster")
    p.add_argument("--address", help="Ray cluster address (default: start a local one)")
    p.add_argument("--frames-per-task", type=positive_int,
                   help=f"frames rendered per Ray task (default {default_of(run_batch, 'frames_per_task')})")
    p.add_argument("--device", default="cpu", type=device_arg, help="torch device (cpu, cuda, cuda:N)")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    add_quiet_option(p)
    add_external_assets_option(p)
    p.set_defaults(func=_batch)

    _add_render_command(sub)

    p = sub.add_parser("demo", help="run the built-in street world end to end and write an illustrated report")
    p.add_argument("--out", default="out/demo", help="output directory (default out/demo)")
    p.add_argument("--quick", action="store_true", help="fewer frames and sampler steps, no refinement (minutes)")
    add_quiet_option(p)
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.set_defaults(func=_demo)

    bench = sub.add_parser("bench", help="measurements").add_subparsers(dest="bench", required=True, metavar="BENCH")
    p = bench.add_parser("accuracy-time", help="quality against ground truth and time, knob by knob, in one run")
    p.add_argument("--out", required=True, help="directory for accuracy_time.md/.json and pareto.png")
    p.add_argument("--package", help="scene package with held-out recorded images or ground truth to score against "
                        "(default: the built-in street world)")
    p.add_argument("--quick", action="store_true", help="fewer frames, views and placements per setting")
    add_quiet_option(p)
    add_external_assets_option(p)
    p.set_defaults(func=_accuracy_time)


def _add_window_options(p) -> None:
    """``--frames``, ``--offsets`` and ``--cameras`` of ``plan`` and ``run``: the same window for both."""
    add_frames_option(p, help="the frame window: render, restore and harmonize only these recorded frames "
                              "(default: all; reconstruction fits every frame)")
    add_offsets_option(p, help="lateral views to restore instead of the manifest's effects.lateral_offsets")
    p.add_argument("--cameras", type=names_arg, metavar="NAME,...",
                   help="render, restore and harmonize only these cameras (default: all; reconstruction fits every "
                        "camera that recorded images)")


def _plan_options(args):
    """The plan options of ``plan`` and ``run``: both plan the same run from the same flags."""
    from ..conventions import both_sides
    from ..pipeline.plan import PlanOptions

    return PlanOptions(refine=not args.no_refine, adapt=not args.no_adapt, frames=args.frames,
                       offsets=None if args.offsets is None else tuple(both_sides(args.offsets)), cameras=args.cameras)


def _plan(args) -> int:
    from ..pipeline.plan import format_plan, make_plan
    from ..scene import load_manifest
    from . import write_json

    plan = make_plan(load_manifest(args.package, allow_external=args.allow_external_assets), _plan_options(args))
    if args.json:
        write_json(plan.to_json(), args.json)
    else:
        print(format_plan(plan))
    return 0


def _run(args) -> int:
    from dataclasses import replace

    from ..pipeline.run import run_scene
    from ..pipeline.stages import StageOptions

    stage_options = StageOptions()
    stage_options.sampler = replace(stage_options.sampler, **given(args, max_memory_gib="max_memory"))
    adapt = given(args, "sensor_pairs", iters="adapt_iters", max_seconds="adapt_seconds")
    stage_options.adapt = replace(stage_options.adapt, **adapt)
    report = run_scene(args.package, args.out, options=_plan_options(args),
                       device=args.device, progress=not args.quiet, force=args.force,
                       allow_external=args.allow_external_assets, stage_options=stage_options)
    for s in report["stages"]:
        took = f" ({s['seconds']:.1f} s)" if "seconds" in s else ""
        print(f"{'ran ' if s['ran'] else 'skip'} {s['name']}: {s['reason']}{took}")
    return 0


def _batch(args) -> int:
    reports = run_batch(args.packages, args.out, executor=args.executor, ray_address=args.address,
                        device=args.device, force=args.force, **given(args, "frames_per_task"),
                        progress=not args.quiet,
                        allow_external=args.allow_external_assets)
    for r in reports:
        ran = [s["name"] for s in r["stages"] if s["ran"]]
        print(f"{r['scene']}: ran {', '.join(ran)}")
    return 0


def _accuracy_time(args) -> int:
    from ..bench.accuracy_time import format_table, run_settings, write_outputs
    from ..bench.knobs import WHY_DEFAULTS, package_settings
    from ..pipeline.outputs import output_folder
    from ..scene import load_manifest
    from ..world.demo import DEMO_PACKAGE

    output_folder(args.out)
    manifest = load_manifest(args.package or DEMO_PACKAGE, allow_external=args.allow_external_assets)
    settings, skipped = package_settings(manifest, quick=args.quick)
    for group, why in skipped.items():
        print(f"left out {group} knobs: {why}")
    rows = run_settings(settings, progress=not args.quiet)
    knobs = {r["knob"] for r in rows}
    paths = write_outputs(rows, args.out, {k: v for k, v in WHY_DEFAULTS.items() if k in knobs})
    print(format_table(rows))
    print(f"wrote {paths['md']}, {paths['json']}, {paths['png']}")
    return 0


def _demo(args) -> int:
    from ..world.demo import run_demo

    report = run_demo(args.out, quick=args.quick, progress=not args.quiet, force=args.force)
    print(f"demo finished in {report['demo_seconds']} s: {args.out}/report.md, {args.out}/report.json")
    for key, rows in report["metrics"].items():
        print(f"  {key}: {rows}")
    return 0


def _add_render_command(sub) -> None:
    from . import add_external_assets_option, device_arg

    p = sub.add_parser("render", help="render one camera's frames of a scene package (background and actors) "
                                      "as PNGs, a quick preview without a run")
    p.add_argument("package", help="scene package directory or its manifest.json")
    p.add_argument("--camera", required=True, help="camera name in the manifest")
    add_frames_option(p, help="frames to render (default: the first)")
    p.add_argument("--out", required=True, help="output folder; frames go to render/<camera>/<frame>.png")
    p.add_argument("--width", type=positive_int, help="output width (default: the camera's; aspect kept if only "
                                             "--height is given)")
    p.add_argument("--height", type=positive_int, help="output height (default: the camera's)")
    p.add_argument("--device", default="cpu", type=device_arg, help="torch device (cpu, cuda, cuda:N)")
    add_quiet_option(p)
    add_external_assets_option(p)
    p.set_defaults(func=_render)


def _render(args) -> int:
    from ..pipeline.preview import render_package

    paths = render_package(args.package, args.camera, args.frames, args.out, width=args.width, height=args.height,
                           device=args.device, allow_external=args.allow_external_assets,
                           progress=not args.quiet)
    for p in paths:
        print(p)
    return 0
