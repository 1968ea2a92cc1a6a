"""The docs stay runnable: every ``symdrive`` line in a fenced code block of the READMEs and docs/*.md
parses with the real command line, every command appears in one, every relative link resolves and
every repository path they name exists."""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import shlex
from pathlib import Path

import pytest

from symdrive_core.cli import build_parser

ROOT = Path(__file__).resolve().parents[2]
DOCS = [ROOT / "README.md", ROOT / "blender_addon" / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

# Placeholders the docs write in capitals, and a value of the kind the option expects.
PLACEHOLDERS = {
    "A:B": "0:3", "N": "2", "S": "1", "H": "1.5", "GiB": "4", "HOST:PORT": "127.0.0.1:6379",
    "MODULE:CLASS": "agents:Agent", "LIST": "0:3,7",
}
FENCE = re.compile(r"^```.*?^```", re.S | re.M)
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def _fenced_lines(text: str):
    """(line number, logical line) of every fenced code block, continuations joined, comments cut."""
    for block in FENCE.finditer(text):
        first = text.count("\n", 0, block.start()) + 1
        pending, start = "", None
        for offset, raw in enumerate(block.group(0).splitlines()[1:-1]):
            line = raw.split(" # ")[0].split("\t# ")[0].rstrip()
            if line.lstrip().startswith("#"):
                line = ""
            start = first + 1 + offset if start is None else start
            if line.endswith("\\"):
                pending += line[:-1] + " "
                continue
            yield start, (pending + line).strip()
            pending, start = "", None


def _variants(line: str) -> list[list[str]]:
    """The argument lists a synopsis stands for: brackets opened, each alternative of ``a|b`` once,
    ``...`` dropped, placeholders filled in."""
    tokens = [t.replace("[", "").replace("]", "") for t in shlex.split(line)[1:]]
    tokens = [PLACEHOLDERS.get(t, "x" if re.fullmatch(r"[A-Z][A-Z0-9_]*", t) else t)
              for t in tokens if t and t != "..."]
    choices = [t.split("|") if "|" in t else [t] for t in tokens]
    variants = [[c[0] for c in choices]]
    for i, options in enumerate(choices):
        for option in options[1:]:
            variants.append([c[0] for c in choices[:i]] + [option] + [c[0] for c in choices[i + 1:]])
    return variants


def _command_lines():
    for doc in DOCS:
        for number, line in _fenced_lines(doc.read_text(encoding="utf-8")):
            if line.startswith("symdrive "):
                yield pytest.param(line, id=f"{doc.relative_to(ROOT)}:{number}")


COMMAND_LINES = list(_command_lines())


def _parse(args: list[str]) -> tuple[int, str]:
    """Exit status (0: parsed) and the parser's message."""
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            build_parser().parse_args(args)
            return 0, ""
        except SystemExit as exc:
            return int(exc.code or 0), err.getvalue().strip()


def test_the_docs_show_commands():
    assert len(COMMAND_LINES) >= 30


def _command_parser(args: list[str]) -> argparse.ArgumentParser:
    """The parser of the (sub)command ``args`` name."""
    parser = build_parser()
    for token in args:
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not subs or token not in subs[0].choices:
            break
        parser = subs[0].choices[token]
    return parser


@pytest.mark.parametrize("line", COMMAND_LINES)
def test_each_command_line_in_the_docs_parses(line):
    for args in _variants(line):
        status, message = _parse(args)
        assert status == 0, f"{' '.join(args)}: {message}"
        # spelled out, not a prefix argparse happens to accept
        known = _command_parser(args)._option_string_actions
        abbreviated = [t for t in args if t.startswith("--") and t.split("=")[0] not in known]
        assert not abbreviated, f"{' '.join(args)}: not the option's full name: {abbreviated}"


def _leaf_commands(parser: argparse.ArgumentParser, prefix: tuple[str, ...] = ()):
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield prefix
    for action in subs:
        for name, sub in action.choices.items():
            yield from _leaf_commands(sub, (*prefix, name))


def test_every_command_is_shown_in_the_docs():
    leaves = set(_leaf_commands(build_parser()))
    shown = set()
    for param in COMMAND_LINES:
        for args in _variants(param.values[0]):
            if _parse(args)[0] == 0 and args:
                shown.add(tuple(args[:1]) if tuple(args[:1]) in leaves else tuple(args[:2]))
    missing = sorted(" ".join(c) for c in leaves - shown)
    assert not missing, f"commands no doc shows in a code block: {missing}"


def _relative_links():
    for doc in DOCS:
        text = FENCE.sub("", doc.read_text(encoding="utf-8"))
        text = re.sub(r"`[^`\n]*`", "", text)
        for target in LINK.findall(text):
            if re.match(r"[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):
                continue
            yield pytest.param(doc, target.split("#")[0], id=f"{doc.relative_to(ROOT)}->{target}")


RELATIVE_LINKS = list(_relative_links())


def test_the_docs_link_each_other():
    assert any(doc.name == "README.md" and target.startswith("docs/") for doc, target in
               (p.values for p in RELATIVE_LINKS))


@pytest.mark.parametrize("doc, target", RELATIVE_LINKS)
def test_each_relative_link_resolves(doc, target):
    assert (doc.parent / target).exists(), f"{doc.relative_to(ROOT)} links to {target}, which does not exist"


def test_each_repository_path_the_docs_name_exists():
    named = {path.rstrip(".,:") for doc in DOCS
             for path in re.findall(r"`((?:symdrive_core|scripts|tests|blender_addon|docs)/[^`\s:]*)", doc.read_text())}
    assert len(named) >= 20
    missing = sorted(path for path in named if not (ROOT / path).exists())
    assert not missing, f"the docs name files that do not exist: {missing}"
