"""``symdrive`` command line: thin dispatch to the library.

Each area registers its own subcommands from a light ``commands`` module (heavy imports happen
inside the handlers, so ``symdrive plan`` never loads torch or a diffusion model). Errors in the
user's input print one line naming the file and field and exit with status 2.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys

from .errors import SymDriveError

# Modules that add subcommands; each defines ``add_commands(subparsers)``.
COMMAND_MODULES = [
    "symdrive_core.commands",
    "symdrive_core.optim.commands",
    "symdrive_core.diffusion.commands",
    "symdrive_core.traffic.commands",
    "symdrive_core.insertion.commands",
    "symdrive_core.pipeline.commands",
    "symdrive_core.importers.commands",
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="symdrive", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).add_commands(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    args.invocation = " ".join(["symdrive", *argv])  # recorded in outputs for reproduction
    try:
        return int(args.func(args) or 0)
    except SymDriveError as exc:
        print(f"symdrive {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"symdrive {args.command}: interrupted", file=sys.stderr)
        return 130


def add_external_assets_option(p: argparse.ArgumentParser) -> None:
    """``--allow-external-assets`` for every command that reads a scene package."""
    p.add_argument("--allow-external-assets", action="store_true",
                   help="read asset files outside the package (absolute paths, '..', links leading out), as "
                        "an add-on export without --copy-assets needs; only for packages you trust")


def print_json(obj) -> None:
    print(json.dumps(obj, indent=1))


if __name__ == "__main__":
    sys.exit(main())
