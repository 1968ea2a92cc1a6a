"""Pipeline subcommands: ``plan`` (what a scene needs, without running it)."""

from __future__ import annotations


def add_commands(sub) -> None:
    p = sub.add_parser("plan", help="print the stages a scene package needs, and why, without running them")
    p.add_argument("package", help="scene package directory or its manifest.json")
    p.add_argument("--no-refine", action="store_true", help="plan without 3DGS refinement")
    p.add_argument("--json", action="store_true", help="print the plan as JSON")
    p.set_defaults(func=_plan)


def _plan(args) -> int:
    from ..cli import print_json
    from ..scene import load_manifest
    from .plan import PlanOptions, format_plan, make_plan

    plan = make_plan(load_manifest(args.package), PlanOptions(refine=not args.no_refine))
    if args.json:
        print_json(plan.to_json())
    else:
        print(format_plan(plan))
    return 0
