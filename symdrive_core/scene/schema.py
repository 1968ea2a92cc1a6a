"""The manifest's JSON Schema (``manifest.schema.json``), checked by jsonschema when a manifest is
loaded: every key, type and range the format defines, an unknown key named with the nearest known
one ("did you mean 'harmonize'?"). The reader in ``manifest.py`` then checks what a schema cannot
say (cameras and frames that exist, rigid poses, paths inside the package).

Blender's Python has no jsonschema: in the add-on the reader's own checks of every field it reads
apply (types, ranges, names, paths), and keys it does not read are not reported.
"""

from __future__ import annotations

import difflib
import functools
import json
import math
import re
from pathlib import Path
from typing import Any

from ..errors import InputError
from .paths import check_name, check_path_text, check_relative

SCHEMA_PATH = Path(__file__).with_name("manifest.schema.json")

_TYPE_WORDS = {"object": "an object", "array": "a list", "string": "a string", "boolean": "true or false",
               "null": "null", "integer": "an integer", "number": "a finite number"}


@functools.cache
def manifest_schema() -> dict:
    return json.loads(SCHEMA_PATH.read_text(encoding="utf-8"))


@functools.cache
def _validator():
    """A Draft 2020-12 validator of the schema, or None where jsonschema is not installed."""
    try:
        import jsonschema
    except ImportError:
        return None
    return jsonschema.Draft202012Validator(manifest_schema())


def field_path(parts) -> str:
    """``cameras[0].frames[3].K`` from a JSON location (keys and list indices)."""
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out or "(root)"


def _unknown_keys(error) -> list[str]:
    props, patterns = error.schema.get("properties", {}), error.schema.get("patternProperties", {})
    return [k for k in error.instance if k not in props and not any(re.search(p, k) for p in patterns)]


def _did_you_mean(key: str, known: list[str]) -> str:
    if not known:
        return " (keys are frame indices: 0, 1, ...)"
    near = difflib.get_close_matches(key, known, n=1)
    return f"; did you mean {near[0]!r}?" if near else f"; known: {', '.join(known)}"


# A string the schema marks with one of these formats is explained by the rule that defines it
# (the same function the reader and the output tree use), not by its regular expression.
FORMAT_RULES = {"name": check_name, "path": check_path_text,
                "relative-folder": lambda v, where: check_relative(check_path_text(v, where), where)}


def _rule_message(schema: dict, value: Any) -> str | None:
    rule = FORMAT_RULES.get(schema.get("format"))
    if rule is None or not isinstance(value, str):
        return None
    try:
        rule(value, "value")
    except InputError as exc:
        return exc.message
    return None


def describe(error) -> tuple[str, str]:
    """(field, message) for one jsonschema error, in the words the rest of the loader uses."""
    where, v, kind, rule = list(error.absolute_path), error.instance, error.validator, error.validator_value
    explained = _rule_message(error.schema, v) if kind != "type" else None
    if explained:
        return field_path(where), explained
    if isinstance(v, float) and not math.isfinite(v):  # JSON has no such number; Python's reader lets it in
        return field_path(where), f"expected a finite number, got {v}"
    if kind == "additionalProperties":
        key = _unknown_keys(error)[0]
        return field_path([*where, key]), "unknown field" + _did_you_mean(key, list(error.schema.get("properties", {})))
    if kind == "required":
        missing = next(k for k in rule if k not in v)
        return field_path([*where, missing]), "required field is missing"
    if kind in ("minItems", "maxItems") and error.schema.get("minItems") == error.schema.get("maxItems"):
        n, items = rule, error.schema.get("items", {})
        what = "numbers" if items.get("type") == "number" else ("rows" if items.get("type") == "array" else "entries")
        return field_path(where), f"expected {n} {what}, got {len(v)}"
    text = {
        "type": lambda: "expected " + " or ".join(_TYPE_WORDS[t] for t in ([rule] if isinstance(rule, str) else rule))
                        + f", got {v!r:.60}",
        "minimum": lambda: f"expected a value >= {rule}, got {v}",
        "maximum": lambda: f"expected a value <= {rule}, got {v}",
        "exclusiveMinimum": lambda: f"expected a value > {rule}, got {v}",
        "exclusiveMaximum": lambda: f"expected a value < {rule}, got {v}",
        "minItems": lambda: f"expected at least {rule} entries, got {len(v)}",
        "maxItems": lambda: f"expected at most {rule} entries, got {len(v)}",
        "minLength": lambda: "expected a non-empty string" if rule == 1 else f"expected at least {rule} characters",
        "maxLength": lambda: f"expected at most {rule} characters, got {len(v)}",
        "pattern": lambda: f"{v!r:.60} is not allowed here",
        "enum": lambda: f"expected one of {', '.join(map(repr, rule))}, got {v!r:.60}",
        "const": lambda: f"expected {rule!r}, got {v!r:.60}",
    }.get(kind, lambda: error.message)()
    if "description" in error.schema and kind in ("pattern", "const", "enum"):
        text += f" ({error.schema['description']})"
    return field_path(where), text


def _leaf(error):
    """The error to report for one that comes from ``anyOf``: the alternative that got furthest."""
    while error.context:
        error = max(error.context, key=lambda e: (len(e.absolute_path), e.validator != "type"))
    return error


def schema_problems(data: Any) -> list[tuple[str, str]] | None:
    """Every (field, message) the schema finds in ``data``, unknown keys first (a suggestion for
    one explains a "missing" field); None where jsonschema is not installed."""
    validator = _validator()
    if validator is None:
        return None
    errors = sorted(validator.iter_errors(data), key=lambda e: e.validator != "additionalProperties")
    return [describe(_leaf(e)) for e in errors]
