"""The import graph of ``symdrive_core``: no library module imports the command line, and no
modules import each other in a circle.

Every module is parsed with ``ast`` (nothing is imported), relative imports are resolved against
the module's package, and ``from PKG import NAME`` counts as an import of ``PKG.NAME`` when that is
a module, else of ``PKG``. An edge goes to the module named, not to the packages above it: Python
runs a package's ``__init__`` first, but a submodule importing its own package is not a circle
anyone has to untangle.

Two kinds of import, two rules:

* **Module level** (the module body, class bodies, ``try``/``if`` blocks; not ``if TYPE_CHECKING``):
  these run when the module is imported, so a circle among them makes the import order matter.
  No circle is allowed at this level.
* **Function level** (inside a ``def`` or ``lambda``): how the project defers heavy imports (torch,
  diffusers) until a command needs them. A circle that uses one of these edges works at run time,
  but it still says two modules share a helper that has no home of its own, so it fails too: give
  the shared helper its own module.

``symdrive_core.cli`` is the command line: only modules inside ``cli/`` may import it, at either
level (and not through ``importlib.import_module`` either). The library keeps its own defaults
(the config dataclasses, ``config.py`` beside the code that uses them); the options read them from there.
"""

from __future__ import annotations

import ast
from pathlib import Path

import symdrive_core

ROOT = Path(symdrive_core.__file__).parent
CLI = "symdrive_core.cli"

def _modules() -> dict[str, tuple[Path, bool]]:
    """Dotted name -> (file, is a package ``__init__``) for every module of ``symdrive_core``."""
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
        is_pkg = parts[-1] == "__init__"
        out[".".join(parts[:-1] if is_pkg else parts)] = (path, is_pkg)
    return out


MODULES = _modules()


def _owner(name: str) -> str | None:
    """The module ``name`` is, or the nearest package above it (``pkg.mod.attr`` -> ``pkg.mod``)."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _targets(module: str, is_pkg: bool, node: ast.Import | ast.ImportFrom) -> list[str]:
    """The ``symdrive_core`` modules one import statement names."""
    if isinstance(node, ast.Import):
        names = [a.name for a in node.names]
    else:
        if node.level:
            base = module.split(".") if is_pkg else module.split(".")[:-1]
            base = base[: len(base) - (node.level - 1)]
            pkg = ".".join(base + ([node.module] if node.module else []))
        else:
            pkg = node.module or ""
        names = [f"{pkg}.{a.name}" if f"{pkg}.{a.name}" in MODULES else pkg for a in node.names]
    return [t for t in (_owner(n) for n in names if n.split(".")[0] == "symdrive_core") if t and t != module]


def _dynamic_targets(node: ast.Call) -> list[str]:
    """``importlib.import_module("symdrive_core....")`` / ``__import__(...)`` with a literal name."""
    func = node.func
    name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)
    if name not in ("import_module", "__import__") or not node.args:
        return []
    arg = node.args[0]
    if isinstance(arg, ast.Constant) and isinstance(arg.value, str) and arg.value.startswith("symdrive_core"):
        return [t for t in [_owner(arg.value)] if t]
    return []


def _graph() -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    """(module-level edges, all edges) between ``symdrive_core`` modules."""
    top: dict[str, set[str]] = {m: set() for m in MODULES}
    every: dict[str, set[str]] = {m: set() for m in MODULES}

    def walk(node: ast.AST, module: str, is_pkg: bool, at_top: bool) -> None:
        for child in ast.iter_child_nodes(node):
            child_top = at_top
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                child_top = False
            elif isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                child_top = False
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                targets = _targets(module, is_pkg, child)
            elif isinstance(child, ast.Call):
                targets = _dynamic_targets(child)
            else:
                targets = []
            every[module].update(targets)
            if at_top and not isinstance(child, ast.Call):
                top[module].update(targets)
            walk(child, module, is_pkg, child_top)

    for module, (path, is_pkg) in MODULES.items():
        walk(ast.parse(path.read_text(encoding="utf-8"), str(path)), module, is_pkg, True)
    return top, every


def _cycles(edges: dict[str, set[str]]) -> list[frozenset[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(edges[w]))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = set()
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.add(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    found.append(frozenset(comp))
    return found


TOP, EVERY = _graph()


def test_the_parser_sees_the_project_imports():
    # a check of the checker: edges the project is known to have, at the right level
    assert "symdrive_core.errors" in TOP["symdrive_core.cli"]
    assert "symdrive_core.diffusion.config" in TOP["symdrive_core.pipeline.stages"]
    call = ast.parse('importlib.import_module("symdrive_core.cli.optim")').body[0].value
    assert _dynamic_targets(call) == ["symdrive_core.cli.optim"]
    assert "symdrive_core.pipeline.preview" in EVERY["symdrive_core.cli.pipeline"]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [frozenset("abc")]


def test_no_library_module_imports_the_command_line():
    bad = sorted(f"{m} imports {t}" for m, targets in EVERY.items() if not (m == CLI or m.startswith(CLI + "."))
                 for t in targets if t == CLI or t.startswith(CLI + "."))
    assert bad == [], "the library must not import symdrive_core.cli (move the shared value into the library):\n" \
        + "\n".join(bad)


def test_no_import_cycle_at_module_level():
    cycles = [sorted(c) for c in _cycles(TOP)]
    assert cycles == [], f"modules importing each other at module level: {cycles}"


def test_no_cycle_through_deferred_imports_either():
    cycles = [sorted(c) for c in _cycles(EVERY)]
    assert cycles == [], f"an import circle (move the shared helper to a module of its own): {cycles}"


def test_the_library_does_not_import_the_demo_world():
    """Only the command line reaches the demo world (``symdrive demo`` runs it)."""
    world, cli = "symdrive_core.world", "symdrive_core.cli"
    bad = sorted(f"{m} imports {t}" for m, targets in EVERY.items() if not (_inside(m, world) or _inside(m, cli))
                 for t in targets if _inside(t, world))
    assert bad == [], "symdrive_core.world builds and runs the demo package only:\n" + "\n".join(bad)


def _inside(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def test_the_pipeline_does_not_import_the_benchmarks():
    bad = sorted(f"{m} imports {t}" for m, targets in EVERY.items() if _inside(m, "symdrive_core.pipeline")
                 for t in targets if _inside(t, "symdrive_core.bench"))
    assert bad == [], "symdrive_core.bench measures the pipeline; the pipeline must not depend on it:\n" + "\n".join(bad)


# The layers, bottom first: a package (or top-level module) imports only itself and those listed
# before it, at module level or inside a function. Data readers sit low (a manifest's road in
# scene/, a vehicle's size and mesh files in io/), so the packages that use them sit above.
LAYERS = (
    "errors", "conventions", "rotations", "gaussians", "metrics",  # plain numpy
    "io",  # files in and out
    "scene",  # the package: manifest, cameras, poses, road, ground truth
    "splat",  # the renderer
    "shadows",  # vehicles' sun shadows on the ground: cast, learnt, the region they may cover
    "optim",  # fitting: reconstruction, fine-tuning
    "importers",  # recorded drives in
    "diffusion",  # the restorer and its chain
    "traffic",  # SUMO traffic into a package
    "insertion",  # inserted vehicles
    "eval",  # the scorers: held-out, lateral, the restoration study, insertion, lane paint
    "pipeline",  # plan and stages
    "sim",  # the closed loop
    "bench",  # measurements of the pipeline
    "world",  # the demo world and the demo run (only the command line imports it)
    "cli",  # the command line
)


def _layer(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def test_the_layers_name_every_package():
    assert {_layer(m) for m in MODULES} - {""} == set(LAYERS)


def test_no_import_reaches_up_a_layer():
    rank = {name: i for i, name in enumerate(LAYERS)}
    bad = sorted(f"{m} imports {t}" for m, targets in EVERY.items() if _layer(m)
                 for t in targets if _layer(t) and rank[_layer(t)] > rank[_layer(m)])
    assert bad == [], "an import from a lower layer to a higher one (move the shared piece down):\n" + "\n".join(bad)
