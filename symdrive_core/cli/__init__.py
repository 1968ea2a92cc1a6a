"""``symdrive`` command line: thin dispatch to the library.

Each area registers its own subcommands from a light module of this package (``cli/optim.py``,
``cli/diffusion.py``, ...; heavy imports happen inside the handlers, so ``symdrive plan`` never
loads torch or a diffusion model). The library never imports this package; defaults live in the
library's config dataclasses: flags default to None, fall back to the config (:func:`given`), and
help texts print the config's value (:func:`default_of`). Errors in the user's input print one line
naming the file and field and exit with status 2.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import importlib
import inspect
import json
import os
import sys
import warnings

from ..errors import SymDriveError, one_line

# Modules that add subcommands; each defines ``add_commands(subparsers)``.
COMMAND_MODULES = [
    "symdrive_core.cli.foundation",
    "symdrive_core.cli.optim",
    "symdrive_core.cli.diffusion",
    "symdrive_core.cli.traffic",
    "symdrive_core.cli.insertion",
    "symdrive_core.cli.pipeline",
    "symdrive_core.cli.sim",
    "symdrive_core.cli.importers",
]


class _Parser(argparse.ArgumentParser):
    """Unknown options are reported by the command given them (``symdrive plan: error: ...``),
    not by the top-level parser, which would leave the command's name out."""

    def parse_known_args(self, args=None, namespace=None):
        namespace, extras = super().parse_known_args(args, namespace)
        if extras and self._subparsers is None:  # a command, not a group of commands
            self.error(f"unrecognized arguments: {' '.join(extras)}")
        return namespace, extras


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="symdrive", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
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
        with warnings.catch_warnings():
            warnings.showwarning = _warning_line(args.command)
            return int(args.func(args) or 0)
    except BrokenPipeError:  # `symdrive plan | head`: the reader left; nothing more to say
        with contextlib.suppress(OSError, ValueError, AttributeError):  # no flush error at exit either
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except SymDriveError as exc:
        print(f"symdrive {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"symdrive {args.command}: interrupted", file=sys.stderr)
        return 130


def _warning_line(command: str):
    """Library warnings as one line each, like errors (not Python's file, line and source echo)."""

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        print(f"symdrive {command}: warning: {one_line(str(message))}", file=sys.stderr)

    return show


def add_external_assets_option(p: argparse.ArgumentParser) -> None:
    """``--allow-external-assets`` for every command that reads a scene package."""
    p.add_argument("--allow-external-assets", action="store_true",
                   help="read asset files outside the package (absolute paths, '..', links leading out), as "
                        "an add-on export without --copy-assets needs; only for packages you trust")


def positive_int(value: str) -> int:
    """A count that must be at least 1 (steps, samples, iterations, sizes): 0 or less is an error,
    not a silent fall-back to the default."""
    return _int_at_least(value, 1)


def count_int(value: str) -> int:
    """A count that may be 0 (warm-up steps, fine-tune iterations, vehicles)."""
    return _int_at_least(value, 0)


def unit_fraction(value: str) -> float:
    """A share from 0 to 1 (a restorer's strength)."""
    return _float_between(value, 0.0, 1.0, "a number from 0 to 1", "from 0 to 1")


def angle_deg(value: str) -> float:
    """An angle from 0 to 90 degrees (a size seen from afar)."""
    return _float_between(value, 0.0, 90.0, "a number of degrees", "from 0 to 90 degrees")


def positive_number(value: str) -> float:
    """A finite number above 0 (a size, a rate, a memory budget, a duration)."""
    x = _float_between(value, 0.0, sys.float_info.max, "a number", "a finite number above 0")
    if x == 0:
        raise argparse.ArgumentTypeError(f"must be a finite number above 0, got {value}")
    return x


def share_above_zero(value: str) -> float:
    """A share above 0 and at most 1 (the highest noise level trained on)."""
    x = unit_fraction(value)
    if x == 0:
        raise argparse.ArgumentTypeError(f"must be above 0 and at most 1, got {value}")
    return x


SEED_MAX = 2**63 - 1  # torch and numpy seeds are 64-bit


def seed_int(value: str) -> int:
    """``--seed``: a whole number from 0 to 2^63 - 1, what every random generator here takes."""
    n = _int_at_least(value, 0)
    if n > SEED_MAX:
        raise argparse.ArgumentTypeError(f"must be at most {SEED_MAX} (a 64-bit seed), got {n}")
    return n


def number_at_least_zero(value: str) -> float:
    """A finite number, 0 or more (0 meaning none or off where the option says so)."""
    return _float_between(value, 0.0, sys.float_info.max, "a number", "a finite number, 0 or more")


def loss_weight(value: str) -> float:
    """A loss term's weight: finite and at least 0 (0: the term is off)."""
    return number_at_least_zero(value)


def _float_between(value: str, low: float, high: float, expected: str, bounds: str) -> float:
    try:
        x = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {expected}, got {value!r}") from None
    if not low <= x <= high:
        raise argparse.ArgumentTypeError(f"must be {bounds}, got {value}")
    return x


def _int_at_least(value: str, low: int) -> int:
    try:
        n = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {value!r}") from None
    if n < low:
        raise argparse.ArgumentTypeError(f"must be at least {low}, got {n}")
    return n


def device_arg(value: str) -> str:
    """``--device``: a torch device this machine has (cpu, cuda, cuda:N), checked up front."""
    if value == "cpu":
        return value
    import torch

    try:
        device = torch.device(value)
    except (RuntimeError, ValueError):
        raise argparse.ArgumentTypeError(f"{value!r} is not a torch device (cpu, cuda, cuda:N)") from None
    if device.type == "cuda":
        if not torch.cuda.is_available():
            raise argparse.ArgumentTypeError(
                f"{value!r}: CUDA is not available here (torch {torch.__version__}"
                f"{', a CPU-only build' if torch.version.cuda is None else ', no GPU found'}); use --device cpu")
        if device.index is not None and device.index >= torch.cuda.device_count():
            raise argparse.ArgumentTypeError(f"{value!r}: this machine has {torch.cuda.device_count()} GPU(s)")
    elif device.type != "cpu":
        raise argparse.ArgumentTypeError(f"{value!r}: only cpu and cuda devices are supported")
    return value


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("symdrive")
    except PackageNotFoundError:
        return "unknown (not installed)"


def print_json(obj) -> None:
    print(json.dumps(obj, indent=1))


FRAMES_MAX = 1_000_000


def frames_arg(text: str) -> list[int]:
    """``--frames`` of every command: ``0:3,7,10:12``, single indices and inclusive ranges ``A:B``.

    One syntax for every command, so a list that works for ``render`` works for ``restore``.
    Returns the indices in order, duplicates dropped; whether the package has them is checked
    by the command once it has read the package.
    """
    frames: dict[int, None] = {}  # ordered, without repeats
    for item in text.split(","):
        item = item.strip()
        if not item:
            raise argparse.ArgumentTypeError(f"empty item in {text!r} (expected e.g. 0:3,7)")
        if item.startswith("-"):
            raise argparse.ArgumentTypeError(f"frame indices are 0 or more, got {item!r}")
        ends = item.split(":")
        if len(ends) > 2 or not all(e.strip().isdecimal() for e in ends):
            raise argparse.ArgumentTypeError(f"expected frame indices A or ranges A:B (e.g. 0:3,7), got {item!r}")
        a, b = int(ends[0]), int(ends[-1])
        if b < a:
            raise argparse.ArgumentTypeError(f"range {item!r} runs backwards (expected A:B with A <= B)")
        if b - a + 1 + len(frames) > FRAMES_MAX:  # a typo like 0:999999999 fails here, not out of memory
            raise argparse.ArgumentTypeError(f"{text!r} names more than {FRAMES_MAX:,} frames")
        frames.update(dict.fromkeys(range(a, b + 1)))
    return list(frames)


def add_frames_option(p: argparse.ArgumentParser, flag: str = "--frames", *, help: str) -> None:
    """A frame-list option (``--frames``, ``--refine-frames``) in the one syntax of :func:`frames_arg`."""
    p.add_argument(flag, type=frames_arg, metavar="LIST", help=f"{help}; LIST as 0:3,7 (ranges inclusive)")


def names_arg(text: str) -> tuple[str, ...]:
    """A list of names (cameras, channels): distinct and comma-separated."""
    names = tuple(t.strip() for t in text.split(","))
    if not all(names) or len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(f"expected distinct names separated by commas, got {text!r}")
    return names


def distances_arg(text: str) -> list[float]:
    """``--offsets`` of every command: comma-separated positive distances in metres."""
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated distances in metres, got {text!r}") from None
    if not values or not all(0 < v < float("inf") for v in values):
        raise argparse.ArgumentTypeError(f"expected positive distances in metres, got {text!r}")
    cm = [round(v * 100) for v in values]  # outputs are named by the centimetre (+1.50)
    if len(set(cm)) != len(cm):
        raise argparse.ArgumentTypeError(f"expected distinct distances to the centimetre (outputs are named by it), "
                                         f"got {text!r}")
    return values


def add_offsets_option(p: argparse.ArgumentParser, *, help: str, default: list[float] | None = None) -> None:
    """``--offsets D,...``: lateral distances, each restored on both sides (``conventions.both_sides``)."""
    p.add_argument("--offsets", type=distances_arg, default=default, metavar="D,...",
                   help=f"{help}; each distance d (m) means the views at -d and +d")


def json_target(value: str) -> str:
    """``--json`` FILE or ``-`` (stdout); the folder must exist, so a typo fails before the work."""
    if value == "-":
        return value
    parent = os.path.dirname(os.path.abspath(value))
    if os.path.isdir(value):
        raise argparse.ArgumentTypeError(f"{value!r} is a folder, expected a file")
    if not os.path.isdir(parent):
        raise argparse.ArgumentTypeError(f"folder {parent!r} does not exist")
    return value


def add_json_option(p: argparse.ArgumentParser, what: str, *, optional_file: bool = True) -> None:
    """``--json [FILE]``: the result as JSON, to FILE (written atomically) or, bare or ``-``, to stdout.

    ``optional_file=False`` is for commands that print JSON anyway: FILE is required and ``-``
    adds nothing to what is printed.
    """
    if optional_file:
        p.add_argument("--json", type=json_target, nargs="?", const="-", metavar="FILE",
                       help=f"{what} as JSON: to FILE, or to stdout when bare or FILE is -")
    else:
        p.add_argument("--json", type=json_target, metavar="FILE",
                       help=f"also write {what} (printed as JSON in any case) to FILE; - writes no file")


def write_json(obj, target: str) -> None:
    """Where ``--json`` points: ``-`` prints, a path is written whole or not at all."""
    if target == "-":
        print_json(obj)
        return
    from ..io.atomic import write_text_atomic

    write_text_atomic(target, json.dumps(obj, indent=1) + "\n")


def default_of(owner, name: str) -> str:
    """The default ``--help`` prints for ``name``: a field of a config dataclass (class or instance;
    a dotted name walks into nested configs) or a keyword of a function, read from there so no help
    text restates a number."""
    value = owner
    for part in name.split("."):
        if isinstance(value, type) and dataclasses.is_dataclass(value):
            f = next(f for f in dataclasses.fields(value) if f.name == part)
            value = f.default_factory() if f.default is dataclasses.MISSING else f.default
        elif callable(value) and not dataclasses.is_dataclass(value):
            value = inspect.signature(value).parameters[part].default
        else:
            value = getattr(value, part)
    return f"{value:g}" if isinstance(value, float) else str(value)


def given(args: argparse.Namespace, *names: str, **renamed: str) -> dict:
    """The options the command line set, as config fields: ``names`` are options named as their
    field, ``renamed`` maps a field to its option's name. Left-out flags are None and are left out
    here, so ``dataclasses.replace(config, **given(...))`` falls back to the config."""
    pairs = [(n, n) for n in names] + list(renamed.items())
    return {field: getattr(args, dest) for field, dest in pairs if getattr(args, dest) is not None}


def add_quiet_option(p: argparse.ArgumentParser) -> None:
    """``--quiet`` of every long command; handlers pass ``progress=not args.quiet`` to the library."""
    p.add_argument("--quiet", action="store_true", help="no progress bars")


def add_renamed_option(p: argparse.ArgumentParser, flag: str, old: str, **kwargs) -> None:
    """``flag`` with its former spelling ``old`` still accepted (same value, not in ``--help``), so
    scripts written before the rename keep working; giving both is an error."""
    group = p.add_mutually_exclusive_group(required=kwargs.pop("required", False))
    action = group.add_argument(flag, **kwargs)
    group.add_argument(old, dest=action.dest, type=action.type, metavar=action.metavar,
                       default=argparse.SUPPRESS, help=argparse.SUPPRESS)

