"""Each compositing rule has one home (``splat/constants.py``): no module writes the alpha
threshold, clamp or stop value out again, so changing one is a one-file change."""

import ast
from pathlib import Path

import symdrive_core
from symdrive_core.splat import constants

CORE = Path(symdrive_core.__file__).parent
NAMES = ("ALPHA_THRESHOLD", "ALPHA_MAX", "T_STOP", "EXTENT_CAP", "EPS2D", "FOV_CLAMP_MARGIN")
RULES: dict[float, str] = {}
for _name in NAMES:  # equal values (EPS2D and FOV_CLAMP_MARGIN are both 0.3) share one entry
    RULES[getattr(constants, _name)] = " or ".join(filter(None, (RULES.get(getattr(constants, _name)), _name)))


def _value(node):
    """The number an expression of literals spells (``1.0 / 255.0`` included), else None."""
    try:
        v = ast.literal_eval(node) if not isinstance(node, ast.BinOp) else eval(  # noqa: S307 - literals only
            compile(ast.Expression(node), "<expr>", "eval"), {"__builtins__": {}})
    except Exception:
        return None
    return v if isinstance(v, float) else None


def test_compositing_constants_are_written_only_in_their_module():
    found = []
    for path in sorted(CORE.rglob("*.py")):
        if path == Path(constants.__file__):
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, (ast.BinOp, ast.Constant)):
                v = _value(node)
                # the threshold nowhere else; inside the renderer, none of the rules
                if v == constants.ALPHA_THRESHOLD or (v in RULES and path.parent.name == "splat"):
                    found.append(f"{path.relative_to(CORE)}:{node.lineno} {RULES.get(v, v)}")
    assert not found, "write these as splat.constants names: " + ", ".join(found)


def test_the_scan_sees_a_threshold_spelt_as_a_division():
    assert _value(ast.parse("1.0 / 255.0", mode="eval").body) == constants.ALPHA_THRESHOLD
    assert _value(ast.parse("0.99", mode="eval").body) == constants.ALPHA_MAX
    assert _value(ast.parse("x / 255", mode="eval").body) is None


def test_sh_constants_are_written_only_by_the_gaussians_module():
    """``gaussians.py`` owns the SH basis constants; the numba kernels and the float64 oracle keep
    inline copies on purpose (plain scalars for the kernels, an independent check for the oracle)."""
    from symdrive_core import gaussians

    values = {abs(v) for v in (gaussians.SH_C0, gaussians.SH_C1, *gaussians.SH_C2, *gaussians.SH_C3)}
    own = {Path(gaussians.__file__), CORE / "splat" / "proj_kernels.py", CORE / "splat" / "oracle.py"}
    found = []
    for path in sorted(CORE.rglob("*.py")):
        if path in own:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Constant) and isinstance(node.value, float) and abs(node.value) in values:
                found.append(f"{path.relative_to(CORE)}:{node.lineno} {node.value!r}")
    assert not found, "import these from symdrive_core.gaussians: " + ", ".join(found)
