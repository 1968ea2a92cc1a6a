"""Argument errors exit 2 with ``symdrive COMMAND: error:`` and one line; every option has help."""

import argparse

import pytest

from symdrive_core.cli import build_parser, main
from symdrive_core.pipeline.demo import DEMO_PACKAGE

PKG = str(DEMO_PACKAGE)


def _exit_code(argv) -> int:
    """The status ``symdrive ARGV`` ends with, whether argparse exits or ``main`` returns."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


@pytest.mark.parametrize("argv, command, says", [
    # comma lists: a range, letters
    (["restore", PKG, "--frames", "0:3", "--out", "OUT"], "restore", "argument --frames: expected comma-separated"),
    (["restore", PKG, "--refine-frames", "1:2", "--out", "OUT"], "restore", "argument --refine-frames"),
    (["restore", PKG, "--offsets", "a,b", "--out", "OUT"], "restore", "argument --offsets"),
    (["make-pairs", PKG, "--frames", "x", "--out", "OUT"], "make-pairs", "argument --frames"),
    (["make-pairs", PKG, "--offsets", "0,1", "--out", "OUT"], "make-pairs", "argument --offsets: expected positive"),
    (["make-pairs", PKG, "--cycle", "0", "--out", "OUT"], "make-pairs", "argument --cycle: expected non-zero"),
    # a device this build lacks (CUDA on a CPU-only torch or a GPU index past the last)
    (["run", PKG, "--device", "cuda:99"], "run", "argument --device"),
    (["render", PKG, "--camera", "front", "--device", "tpu", "--out", "OUT"], "render", "argument --device"),
    # plain argparse: a wrong type, a missing required option, a choice not offered
    (["reconstruct", PKG, "--iters", "many"], "reconstruct", "argument --iters"),
    (["restore", PKG], "restore", "--out"),
    (["restore", PKG, "--backend", "sd", "--out", "OUT"], "restore", "argument --backend"),
])
def test_a_bad_argument_exits_2_naming_the_command(tmp_path, capsys, argv, command, says):
    argv = [str(tmp_path / "out") if a == "OUT" else a for a in argv]
    assert _exit_code(argv) == 2
    err = capsys.readouterr().err
    assert f"symdrive {command}: error: " in err and says in err and "Traceback" not in err


@pytest.mark.parametrize("argv, command, says", [
    # checked against the package after parsing: exit 2 through SymDriveError, same prefix
    (["render", PKG, "--camera", "front", "--frames", "0:999", "--out", "OUT"], "render", "--frames"),
    (["render", PKG, "--camera", "nope", "--out", "OUT"], "render", "no camera named 'nope'"),
    (["sim", PKG, "--size", "0x3", "--out", "OUT"], "sim", "--size"),
    (["sim", PKG, "--dt", "0", "--out", "OUT"], "sim", "--dt"),
    (["traffic", PKG, "--density", "1", "--seconds", "1", "--road", "bogus"], "traffic", "--road"),
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


def _parsers(parser: argparse.ArgumentParser, path: str):
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, f"{path} {name}")


def test_every_command_and_option_has_help():
    missing = []
    for path, parser in _parsers(build_parser(), "symdrive"):
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            if isinstance(action, argparse._SubParsersAction):
                missing += [f"{path} {c.dest}" for c in action._choices_actions if not (c.help or "").strip()]
                continue
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
