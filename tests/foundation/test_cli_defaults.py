"""No default is written twice: help texts print the config's value (``default_of``), flags left
out fall back to the config (``given``), and a number argparse owns is printed by argparse."""

import argparse
import ast
import re
from pathlib import Path

import pytest

import symdrive_core.cli as cli
from symdrive_core.cli import build_parser, default_of, given
from symdrive_core.diffusion.config import SAMPLERS, RefineConfig, TrainConfig
from symdrive_core.insertion.config import HarmonizeConfig
from symdrive_core.optim.config import ReconstructConfig
from symdrive_core.pipeline.batch import run_batch
from symdrive_core.pipeline.stages import StageOptions

CLI_FILES = sorted(Path(cli.__file__).parent.glob("*.py"))
LITERAL_DEFAULT = re.compile(r"\bdefault:?\s+-?\.?\d")


def _add_argument_calls(tree):
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "attr", None) in ("add_argument", "add_renamed_option"):
            yield node


@pytest.mark.parametrize("path", CLI_FILES, ids=lambda p: p.name)
def test_no_help_text_restates_a_default_number(path):
    """Literal text only: ``(default {default_of(...)})`` is a formatted value, not a literal."""
    tree = ast.parse(path.read_text())
    bad = [(n.lineno, n.value) for n in ast.walk(tree)
           if isinstance(n, ast.Constant) and isinstance(n.value, str) and LITERAL_DEFAULT.search(n.value)]
    assert bad == []


@pytest.mark.parametrize("path", CLI_FILES, ids=lambda p: p.name)
def test_a_number_the_parser_owns_is_printed_by_the_parser(path):
    for call in _add_argument_calls(ast.parse(path.read_text())):
        kw = {k.arg: k.value for k in call.keywords}
        default = kw.get("default")
        if isinstance(default, ast.Constant) and isinstance(default.value, (int, float)) \
                and not isinstance(default.value, bool):
            help_text = ast.unparse(kw.get("help", ast.Constant("")))
            assert "%(default)s" in help_text, f"{path.name}:{call.lineno}"


def _command(name: str) -> argparse.ArgumentParser:
    parser = build_parser()
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[name]


def _help(command: str) -> str:
    return " ".join(_command(command).format_help().split())


@pytest.mark.parametrize("command,flag,value", [
    ("insert-eval", "--steps", HarmonizeConfig().steps),
    ("insert-eval", "--samples", HarmonizeConfig().samples),
    ("restore", "--refine-iters", RefineConfig().iters),
    ("restore", "--max-memory", f"{StageOptions().sampler.max_memory_gib:g}"),
    ("run", "--max-memory", f"{StageOptions().sampler.max_memory_gib:g}"),
    ("reconstruct", "--max-gaussians", ReconstructConfig().densify.max_gaussians),
    ("reconstruct", "--iters", ReconstructConfig().iters),
    ("reconstruct", "--importance-prune", f"{ReconstructConfig().importance_prune:g}"),
    ("train-restorer", "--ema", TrainConfig().ema),
])
def test_help_prints_the_config_value(command, flag, value):
    assert f"(default {value})" in _command(command)._option_string_actions[flag].help


def test_restore_help_prints_each_backend_sampler():
    text = _help("restore")
    for field in ("steps", "n_start", "samples", "noise_free"):
        expected = ", ".join(f"{getattr(s, field)} {name}" for name, s in SAMPLERS.items())
        assert f"(default: {expected})" in text


def test_default_of_reads_nested_configs_instances_and_function_keywords():
    assert default_of(StageOptions, "sampler.max_memory_gib") == f"{StageOptions().sampler.max_memory_gib:g}"
    assert default_of(StageOptions(), "insertion.finetune.steps") == str(StageOptions().insertion.finetune.steps)
    assert default_of(ReconstructConfig, "lr_shN") == f"{ReconstructConfig().lr_shN:g}"
    assert default_of(run_batch, "frames_per_task") == "4"  # run_batch's own keyword default


def test_given_keeps_only_the_flags_the_command_line_set():
    args = argparse.Namespace(steps=None, samples=3, refine_iters=7, seed=None)
    assert given(args, "steps", "samples", iters="refine_iters", seed="seed") == {"samples": 3, "iters": 7}
    assert HarmonizeConfig(**given(args, "steps", "samples")) == HarmonizeConfig(samples=3)
