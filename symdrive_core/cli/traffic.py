"""``symdrive traffic``: SUMO traffic (and scripted manoeuvres) as the actors of a new scene package."""

from __future__ import annotations

from ..scene.road import road_from_spec
from ..traffic.simulate import TrafficOptions
from . import (
    add_quiet_option,
    default_of,
    given,
    number_at_least_zero,
    positive_int,
    positive_number,
    seed_int,
)


def add_commands(sub) -> None:
    from . import add_external_assets_option

    p = sub.add_parser("traffic", help="simulate traffic on the package's road with SUMO; write a new package "
                                       "whose actors are the vehicles")
    p.add_argument("package", help="scene package directory or its manifest.json")
    p.add_argument("--density", type=number_at_least_zero, required=True, help="vehicles per km per lane (0 = no traffic)")
    p.add_argument("--seconds", type=positive_number, required=True,
                   help="simulated seconds; the frames are the last part of the run, the rest is warm-up")
    p.add_argument("--seed", type=seed_int,
                   help=f"random seed of the demand and of SUMO (default {default_of(TrafficOptions, 'seed')})")
    p.add_argument("--speed", type=number_at_least_zero,
                   help=f"speed limit in m/s, 0 = standing (default {default_of(TrafficOptions, 'speed')})")
    p.add_argument("--manoeuvre", help="manoeuvre spec JSON (cut_in, lane_change, hard_brake), run through TraCI")
    p.add_argument("--assets", nargs="+", help="vehicle asset folders (with wlh.json) or folders holding them; "
                                               "default: the asset folders inside the package")
    p.add_argument("--out", help="output package directory (default: PACKAGE-traffic beside the package)")
    p.add_argument("--road", help="straight:LENGTH or curved:LENGTH:RADIUS instead of the package's road")
    p.add_argument("--lanes", type=positive_int,
                   help=f"lanes of a --road road (default {default_of(road_from_spec, 'lanes')})")
    p.add_argument("--timeout", type=positive_number,
                   help=f"wall-clock limit for SUMO in seconds (default {default_of(TrafficOptions, 'timeout')})")
    add_quiet_option(p)
    add_external_assets_option(p)
    p.set_defaults(func=_traffic)


def _traffic(args) -> int:
    import tempfile
    from pathlib import Path

    from ..errors import InputError
    from ..scene import load_manifest
    from ..scene.road import road_from_json
    from ..traffic.assets import asset_pool
    from ..traffic.manoeuvre_spec import load_manoeuvres
    from ..traffic.package import check_output_path, traffic_manifest, write_package
    from ..traffic.simulate import simulate

    src = load_manifest(args.package, allow_external=args.allow_external_assets)
    if args.road:
        road = road_from_spec(args.road, **given(args, "lanes"))
    elif "road" in src.ground_truth:
        road = road_from_json(src.ground_truth["road"], src.path)
    else:
        raise InputError(src.path, "no road: add one to the package or pass --road straight:LENGTH",
                         "ground_truth.road")
    out = Path(args.out) if args.out else src.root.parent / f"{src.root.name}-traffic"
    check_output_path(src, out)
    assets = asset_pool([Path(a) for a in args.assets] if args.assets else [src.root])
    opt = TrafficOptions(density=args.density, seconds=args.seconds,
                         manoeuvres=load_manoeuvres(args.manoeuvre) if args.manoeuvre else [],
                         **given(args, "seed", "speed", "timeout"))
    with tempfile.TemporaryDirectory(prefix="symdrive-traffic-") as tmp:
        run = simulate(road, [f.timestamp for f in src.frames], assets, opt, Path(tmp), where=str(src.path),
                       progress=not args.quiet)
        manifest, gaps = traffic_manifest(src, road, run, assets, opt, out)
        path = write_package(manifest, Path(tmp))
    print(f"{path}: {len(manifest.actors)} vehicles over {len(manifest.frames)} frames "
          f"({run.vehicles_at_start} on the road at the start; SUMO {run.sumo_seconds:.2f} s)")
    if gaps.min_gap is None:
        print("minimum gap: no frame has two vehicles")
    else:
        print(f"minimum gap: {gaps.min_gap:.3f} m (frame {gaps.frame}, {gaps.pair[0]} and {gaps.pair[1]}); "
              "overlaps: none")
    for m in run.manoeuvres:
        print("manoeuvre: " + ", ".join(f"{k} {v}" for k, v in m.items()))
    return 0
