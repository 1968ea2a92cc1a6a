"""Foundation subcommands: ``validate`` (scene packages) and ``info`` (splat PLY files)."""

from __future__ import annotations

from . import add_json_option


def add_commands(sub) -> None:
    from . import add_external_assets_option

    p = sub.add_parser("validate", help="check a scene package's manifest.json and the files it names")
    p.add_argument("manifest", help="manifest.json or the package directory")
    p.add_argument("--no-files", action="store_true", help="skip the check that referenced files exist")
    add_external_assets_option(p)
    p.set_defaults(func=_validate)

    p = sub.add_parser("info", help="count, SH degree and bounds of a 3DGS splat PLY")
    p.add_argument("ply", help="splat PLY file")
    p.add_argument("--drop-invalid", action="store_true", help="ignore splats with NaN/Inf values")
    add_json_option(p, "count, SH degree and bounds")
    p.set_defaults(func=_info)


def _validate(args) -> int:
    from ..scene import check_files, load_manifest

    m = load_manifest(args.manifest, allow_external=args.allow_external_assets)
    if not args.no_files:
        check_files(m)
    print(f"{m.path}: valid (version 1, {len(m.frames)} frames, {len(m.cameras)} cameras, "
          f"{len(m.actors)} actors)")
    return 0


def _info(args) -> int:
    from ..io.ply import describe, read_splats
    from . import write_json

    info = describe(args.ply, read_splats(args.ply, drop_invalid=args.drop_invalid))
    if args.json:
        write_json(info, args.json)
    else:
        lo, hi = info["bounds_min"], info["bounds_max"]
        print(f"{info['path']}: {info['count']} splats, SH degree {info['sh_degree']}")
        print("  bounds min: " + " ".join(f"{v:.3f}" for v in lo))
        print("  bounds max: " + " ".join(f"{v:.3f}" for v in hi))
        if info["extra_properties"]:
            print("  extra properties: " + ", ".join(info["extra_properties"]))
    return 0
