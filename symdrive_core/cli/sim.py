"""``symdrive sim``: an agent drives the ego through a scene package; scores, report and videos."""

from __future__ import annotations

from . import add_quiet_option, count_int, positive_int, positive_number, seed_int

MIN_SIDE = 8  # pixels: a rendered view smaller than this has no room for the episode video's inset


def add_commands(sub) -> None:
    from . import add_external_assets_option

    p = sub.add_parser("sim", help="closed-loop simulation: an agent drives the ego car through the package; "
                                   "writes report.json (PDM scores) and a video per episode")
    p.add_argument("package", help="scene package directory or its manifest.json")
    p.add_argument("--agent", default="replay", help="replay, idm, cut-in, or MODULE:CLASS (default replay)")
    p.add_argument("--episodes", type=positive_int, default=1, help="episodes to run (default %(default)s)")
    p.add_argument("--seed", type=seed_int, default=0, help="episode i runs from seed S + i (default %(default)s)")
    p.add_argument("--out", required=True, help="output folder (report.json, episode_NNN.mp4)")
    p.add_argument("--size", help="render size WxH instead of the cameras' own, e.g. 256x144")
    p.add_argument("--dt", type=positive_number, help="seconds per step (default: the package's frame interval)")
    p.add_argument("--time-limit", type=positive_number, help="seconds per episode (default: twice the recorded drive)")
    p.add_argument("--traffic", choices=["replay", "sumo"],
                   help="actors on their recorded poses, or SUMO vehicles reacting to the ego")
    p.add_argument("--vehicles", type=count_int, help="SUMO vehicles on the road (with --traffic sumo)")
    p.add_argument("--action", choices=["accel_steer", "waypoint"],
                   help="the agent's action: [acceleration, steering] or [x, y, speed] (ego-frame target point)")
    p.add_argument("--normalized-actions", action="store_true", default=None,
                   help="the agent's actions are scaled to [-1, 1] (a speed to [0, 1]) instead of physical units")
    p.add_argument("--restore", action="store_true", default=None,
                   help="views off the recorded path go through the restorer (loads the diffusion model)")
    p.add_argument("--no-render", dest="render", action="store_false", default=None,
                   help="state observations only (no camera images)")
    p.add_argument("--no-video", action="store_true", help="write no episode videos")
    add_quiet_option(p)
    add_external_assets_option(p)
    p.set_defaults(func=_sim)


def _sim(args) -> int:
    from ..errors import InputError
    from ..sim.config import SimConfig
    from ..sim.runner import run

    if args.episodes < 1:
        raise InputError("--episodes", f"expected at least 1, got {args.episodes}")
    size = None
    if args.size:
        try:
            w, h = (int(v) for v in args.size.lower().split("x"))
            assert w >= MIN_SIDE and h >= MIN_SIDE
        except (ValueError, AssertionError):
            raise InputError("--size", f"expected WxH, whole numbers of at least {MIN_SIDE} pixels (room for the "
                             f"video's road inset), got {args.size!r}") from None
        size = (w, h)
    if args.vehicles is not None and args.traffic != "sumo":
        raise InputError("--vehicles", "places SUMO vehicles: pass --traffic sumo with it")
    if args.restore and args.render is False:
        raise InputError("--restore", "restores rendered views: it does nothing with --no-render")
    given = {"dt": args.dt, "time_limit_s": args.time_limit, "image_size": size, "render": args.render,
             "traffic": args.traffic, "sumo_vehicles": args.vehicles, "action": args.action,
             "normalized_actions": args.normalized_actions, "restore": args.restore}
    cfg = SimConfig(**{k: v for k, v in given.items() if v is not None})  # unset flags keep SimConfig's defaults
    try:
        from ..sim.agents import load_agent

        load_agent(args.agent)
    except (ValueError, ImportError, AttributeError) as exc:
        raise InputError("--agent", str(exc)) from None
    report = run(args.package, args.agent, args.episodes, args.seed, args.out, cfg,
                 video=not args.no_video, allow_external_assets=args.allow_external_assets, progress=not args.quiet,
                 invocation=getattr(args, "invocation", None))
    for e in report["episodes"]:
        s = e["scores"]
        print(f"episode {e['episode']} (seed {e['seed']}): {e['end_reason']} after {e['steps']} steps; "
              f"PDMS {s['pdm_score']:.3f} (NC {s['no_collision']:g}, DAC {s['drivable_area_compliance']:g}, "
              f"TTC {s['ttc']:g}, C {s['comfort']:g}, RC {s['route_completion']:.3f})")
    print(f"mean PDMS {report['summary']['pdm_score']:.3f}; report: {args.out}/report.json")
    return 0
