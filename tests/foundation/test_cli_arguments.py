"""Argument errors exit 2 with ``symdrive COMMAND: error:`` and one line; every option has help."""

import argparse
import json
from pathlib import Path

import pytest

from symdrive_core.cli import build_parser, frames_arg, main
from symdrive_core.io.ply import write_splats
from symdrive_core.world.demo import DEMO_PACKAGE
from tests.conftest import random_gaussians

PKG = str(DEMO_PACKAGE)


def _exit_code(argv) -> int:
    """The status ``symdrive ARGV`` ends with, whether argparse exits or ``main`` returns."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


# Every option that takes frames, with what else its command needs to parse.
FRAME_OPTIONS = [
    (["make-pairs", PKG, "--out", "OUT"], "--frames"),
    (["restore", PKG, "--out", "OUT"], "--frames"),
    (["restore", PKG, "--out", "OUT"], "--refine-frames"),
    (["render", PKG, "--camera", "front", "--out", "OUT"], "--frames"),
]
BAD_FRAMES = [
    ("x", "expected frame indices"),
    ("1,a:3", "expected frame indices"),
    ("1:2:3", "expected frame indices"),
    ("1.5", "expected frame indices"),
    ("1,,2", "empty item"),
    ("3,", "empty item"),
    ("", "empty item"),
    ("5:2", "runs backwards"),
    ("-1", "0 or more"),
    ("0,-2", "0 or more"),
]


@pytest.mark.parametrize("base, option", FRAME_OPTIONS, ids=lambda v: v if isinstance(v, str) else v[0])
@pytest.mark.parametrize("frames, says", BAD_FRAMES, ids=[f for f, _ in BAD_FRAMES])
def test_bad_frame_lists_exit_2_naming_command_and_option(tmp_path, capsys, base, option, frames, says):
    argv = [str(tmp_path / "out") if a == "OUT" else a for a in base] + [f"{option}={frames}"]
    assert _exit_code(argv) == 2
    err = capsys.readouterr().err
    assert f"symdrive {base[0]}: error: argument {option}: " in err and says in err and "Traceback" not in err


@pytest.mark.parametrize("text, frames", [
    ("0:3,7", [0, 1, 2, 3, 7]),
    ("5", [5]),
    ("2:2", [2]),
    ("7,0:3,2,7", [7, 0, 1, 2, 3]),  # duplicates dropped, first place kept
    (" 1 , 4:5 ", [1, 4, 5]),
    ("10:12,0", [10, 11, 12, 0]),
])
def test_frames_parser_reads_indices_and_inclusive_ranges(text, frames):
    assert frames_arg(text) == frames


@pytest.mark.parametrize("base, option", FRAME_OPTIONS, ids=lambda v: v if isinstance(v, str) else v[0])
def test_every_frames_option_takes_the_one_syntax(base, option):
    args = build_parser().parse_args([*base, option, "0:2,5"])
    assert getattr(args, option[2:].replace("-", "_")) == [0, 1, 2, 5]


@pytest.mark.parametrize("argv, command, says", [
    # comma lists of numbers
    (["restore", PKG, "--offsets", "a,b", "--out", "OUT"], "restore", "argument --offsets"),
    (["make-pairs", PKG, "--offsets", "0,1", "--out", "OUT"], "make-pairs", "argument --offsets: expected positive"),
    (["make-pairs", PKG, "--cycle", "0", "--out", "OUT"], "make-pairs", "argument --cycle: expected finite non-zero"),
    # a device this build lacks (CUDA on a CPU-only torch or a GPU index past the last)
    (["run", PKG, "--device", "cuda:99"], "run", "argument --device"),
    (["render", PKG, "--camera", "front", "--device", "tpu", "--out", "OUT"], "render", "argument --device"),
    # numbers that must be finite (and above 0, or 0 or more)
    (["run", PKG, "--max-memory", "nan"], "run", "argument --max-memory: must be a finite number above 0, got nan"),
    (["run", PKG, "--max-memory", "0"], "run", "argument --max-memory: must be a finite number above 0, got 0"),
    (["restore", PKG, "--max-memory", "inf", "--out", "OUT"], "restore", "argument --max-memory: must be a finite"),
    (["restore", PKG, "--step", "nan", "--out", "OUT"], "restore", "argument --step: must be 0 (single view) or a finite step of at least 0.01 m"),
    (["restore", PKG, "--step", "-1", "--out", "OUT"], "restore", "argument --step: must be 0 (single view) or a finite step of at least 0.01 m"),
    (["import", "colmap", "M", "--out", "OUT", "--fps", "inf"], "import colmap", "argument --fps: must be a finite"),
    (["import", "kitti", "S", "--out", "OUT", "--camera-height", "-1.6"], "import kitti",
     "argument --camera-height: must be a finite number above 0"),
    (["sim", PKG, "--dt", "0", "--out", "OUT"], "sim", "argument --dt: must be a finite number above 0"),
    (["sim", PKG, "--seed", "-5", "--out", "OUT"], "sim", "argument --seed: must be at least 0"),
    (["traffic", PKG, "--density", "-1", "--seconds", "1"], "traffic", "argument --density: must be a finite"),
    # plain argparse: a wrong type, a missing required option, a choice not offered
    (["reconstruct", PKG, "--iters", "many"], "reconstruct", "argument --iters"),
    (["restore", PKG], "restore", "--out"),
    (["restore", PKG, "--backend", "sd", "--out", "OUT"], "restore", "argument --backend"),
    (["flux-prompt", "--text-encoders", "TE", "--out", "OUT", "--device", "tpu"], "flux-prompt", "argument --device"),
    # --json FILE into a folder that is not there, or a folder itself
    (["plan", PKG, "--json", "OUT/missing/plan.json"], "plan", "argument --json: folder"),
    (["info", "x.ply", "--json", "OUT/missing/info.json"], "info", "argument --json: folder"),
    (["insert-eval", PKG, "--gaussians", "x.ply", "--json", "OUT/missing/rows.json"], "insert-eval",
     "argument --json: folder"),
    (["plan", PKG, "--json", "."], "plan", "argument --json: '.' is a folder"),
    # renamed options: --samples of insert meant mesh Gaussians (now --mesh-gaussians), so it is gone
    (["insert", PKG, "--actor", "a", "--samples", "100"], "insert", "unrecognized arguments: --samples 100"),
    (["plan", PKG, "--bogus"], "plan", "unrecognized arguments: --bogus"),
    (["import", "colmap", "M", "--out", "OUT", "--bogus"], "import colmap", "unrecognized arguments: --bogus"),
    (["insert-eval", PKG], "insert-eval", "--gaussians is required"),
    (["insert-eval", PKG, "--gaussians", "a.ply", "--background", "b.ply"], "insert-eval",
     "argument --background: not allowed with argument --gaussians"),
])
def test_a_bad_argument_exits_2_naming_the_command(tmp_path, capsys, argv, command, says):
    argv = [a.replace("OUT", str(tmp_path / "out"), 1) if a.startswith("OUT") else a for a in argv]
    assert _exit_code(argv) == 2
    err = capsys.readouterr().err
    assert f"symdrive {command}: error: " in err and says in err and "Traceback" not in err


@pytest.mark.parametrize("argv, command, says", [
    # checked against the package after parsing: exit 2 through SymDriveError, same prefix
    (["render", PKG, "--camera", "front", "--frames", "0:999", "--out", "OUT"], "render", "--frames"),
    (["render", PKG, "--camera", "nope", "--out", "OUT"], "render", "no camera named 'nope'"),
    (["sim", PKG, "--size", "0x3", "--out", "OUT"], "sim", "--size"),
    (["sim", PKG, "--size", "7x40", "--out", "OUT"], "sim", "at least 8 pixels"),
    (["traffic", PKG, "--density", "1", "--seconds", "1", "--road", "bogus"], "traffic", "--road"),
    (["sim", PKG, "--vehicles", "5", "--out", "OUT"], "sim", "--vehicles: places SUMO vehicles"),
    (["sim", PKG, "--restore", "--no-render", "--out", "OUT"], "sim", "--restore: restores rendered views"),
])
def test_a_bad_value_found_after_parsing_exits_2_naming_the_command(tmp_path, capsys, argv, command, says):
    argv = [str(tmp_path / "out") if a == "OUT" else a for a in argv]
    assert _exit_code(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"symdrive {command}: error: ") and says in err and len(err.splitlines()) == 1


def test_restore_frames_outside_the_camera_exit_2(tmp_path, capsys):
    assert _exit_code(["restore", PKG, "--frames", "0,999", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("symdrive restore: error: ") and "--frames 999 is not a frame" in err


# Former spellings, still accepted (same value) but not shown: (argv, hidden, value, dest, expected)
ALIASES = [
    (["insert", PKG, "--actor", "a"], "--background", "bg.ply", "gaussians", Path("bg.ply")),
    (["insert-eval", PKG], "--background", "bg.ply", "gaussians", Path("bg.ply")),
    (["train-restorer", "PAIRS", "--out", "OUT"], "--steps", "7", "iters", 7),
    (["insert-eval", PKG, "--gaussians", "bg.ply"], "--finetune-steps", "0", "finetune_iters", 0),
    (["insert-eval", PKG, "--gaussians", "bg.ply"], "--harmonize-samples", "3", "samples", 3),
]


@pytest.mark.parametrize("argv, hidden, value, dest, expected", ALIASES, ids=[f"{a[0][0]} {a[1]}" for a in ALIASES])
def test_a_former_option_name_still_works_and_stays_out_of_help(argv, hidden, value, dest, expected):
    parser = build_parser()
    args = parser.parse_args([*argv, hidden, value])
    assert getattr(args, dest) == expected
    assert hidden[2:].replace("-", "_") not in vars(args)  # one value, under the new name
    help_text = dict(_parsers(parser, "symdrive"))[f"symdrive {argv[0]}"].format_help()
    assert hidden not in help_text
    assert f"--{dest.replace('_', '-')}" in help_text


def test_a_former_count_name_is_checked_like_the_new_one(capsys):
    assert _exit_code(["train-restorer", "PAIRS", "--out", "OUT", "--steps", "0"]) == 2
    assert "symdrive train-restorer: error: argument --steps: must be at least 1" in capsys.readouterr().err


def test_plan_json_file_holds_what_bare_json_prints(tmp_path, capsys):
    assert main(["plan", PKG, "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    for argv in (["--json", str(tmp_path / "plan.json")], [f"--json={tmp_path / 'again.json'}"]):
        assert main(["plan", PKG, *argv]) == 0
        assert capsys.readouterr().out == ""  # the file, not stdout
    assert json.loads((tmp_path / "plan.json").read_text()) == printed
    assert json.loads((tmp_path / "again.json").read_text()) == printed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["again.json", "plan.json"]  # no temporary left
    assert main(["plan", PKG, "--json", "-"]) == 0
    assert json.loads(capsys.readouterr().out) == printed


def test_info_json_file_holds_what_bare_json_prints(tmp_path, capsys):
    ply = tmp_path / "splats.ply"
    write_splats(ply, random_gaussians(20, 1, 0))
    assert main(["info", str(ply), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["count"] == 20 and printed["sh_degree"] == 1
    assert main(["info", str(ply), "--json", str(tmp_path / "info.json")]) == 0
    assert capsys.readouterr().out == "" and json.loads((tmp_path / "info.json").read_text()) == printed


def test_insert_eval_json_takes_a_file_or_stdout(tmp_path):
    parse = build_parser().parse_args
    base = ["insert-eval", PKG, "--gaussians", "bg.ply"]
    assert parse([*base, "--json", "-"]).json == "-"
    assert parse([*base, "--json", str(tmp_path / "rows.json")]).json == str(tmp_path / "rows.json")
    assert parse(base).json is None


# Every command that runs long enough for a progress bar, with what else it needs to parse.
LONG_COMMANDS = [
    ["reconstruct", PKG],
    ["make-pairs", PKG, "--out", "OUT"],
    ["train-restorer", "PAIRS", "--out", "OUT"],
    ["restore", PKG, "--out", "OUT"],
    ["insert", PKG, "--actor", "a"],
    ["insert-eval", PKG, "--gaussians", "bg.ply"],
    ["import", "colmap", "M", "--out", "OUT"],
    ["import", "nerfstudio", "T.json", "--out", "OUT"],
    ["import", "3dgs", "M", "--out", "OUT"],
    ["sim", PKG, "--out", "OUT"],
    ["traffic", PKG, "--density", "1", "--seconds", "1"],
    ["batch", PKG, "--out", "OUT"],
    ["run", PKG],
    ["render", PKG, "--camera", "front", "--out", "OUT"],
    ["demo"],
    ["bench", "accuracy-time", "--out", "OUT"],
]


@pytest.mark.parametrize("argv", LONG_COMMANDS, ids=lambda a: " ".join(a[:2] if a[0] in ("import", "bench") else a[:1]))
def test_every_long_command_takes_quiet(argv):
    parser = build_parser()
    assert parser.parse_args([*argv, "--quiet"]).quiet is True
    assert parser.parse_args(argv).quiet is False


def _parsers(parser: argparse.ArgumentParser, path: str):
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, f"{path} {name}")


def test_every_command_and_option_has_help():
    missing = []
    for path, parser in _parsers(build_parser(), "symdrive"):
        shown = {a.dest for a in parser._actions if a.help != argparse.SUPPRESS}
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            if isinstance(action, argparse._SubParsersAction):
                missing += [f"{path} {c.dest}" for c in action._choices_actions if not (c.help or "").strip()]
                continue
            if action.help == argparse.SUPPRESS and action.dest in shown:
                continue  # a former spelling of a shown option (see ALIASES)
            if not (action.help or "").strip() or action.help == argparse.SUPPRESS:
                missing.append(f"{path} {'/'.join(action.option_strings) or action.dest}")
    assert missing == [], f"options without help: {missing}"


@pytest.mark.parametrize("argv", [
    ["restore", "PKG", "--out", "OUT", "--steps", "0"],
    ["restore", "PKG", "--out", "OUT", "--samples", "-1"],
    ["reconstruct", "PKG", "--iters", "-5"],
    ["batch", "PKG", "--out", "OUT", "--frames-per-task", "0"],
    ["train-restorer", "PAIRS", "--out", "OUT", "--batch", "0"],
    ["sim", "PKG", "--out", "OUT", "--vehicles", "-2"],
    ["sim", "PKG", "--out", "OUT", "--episodes", "0"],
    ["render", "PKG", "--camera", "front", "--out", "OUT", "--width", "0"],
])
def test_counts_below_their_minimum_exit_2_naming_the_option(capsys, argv):
    """A count of 0 (or less) is an error naming the option, not a silent fall-back to the default."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    err = capsys.readouterr().err
    option = argv[-2]  # the offending option is the last one given
    assert exc.value.code == 2 and f"symdrive {argv[0]}: error: argument {option}" in err and "at least" in err


def test_a_huge_frame_range_is_refused_when_parsed(capsys):
    assert _exit_code(["render", PKG, "--camera", "front", "--frames", "0:999999999", "--out", "OUT"]) == 2
    err = capsys.readouterr().err
    assert "symdrive render: error: argument --frames" in err and "more than" in err
