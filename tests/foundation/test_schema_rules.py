"""Schema and loader cannot disagree: every rule of ``manifest.schema.json`` that a real manifest
reaches is broken once, and the loader refuses each broken manifest naming the broken field
(``ManifestError``, which the command line turns into exit 2)."""

import copy
import json
import re

import pytest

from symdrive_core.cli import main
from symdrive_core.scene import parse_manifest
from symdrive_core.scene.manifest import ManifestError
from symdrive_core.scene.schema import field_path, manifest_schema
from symdrive_core.world.demo import DEMO_PACKAGE
from tests.conftest import manifest_dict
from tests.foundation.test_ground_truth_schema import TRAFFIC_GT

BAD_STRINGS = ["", ".hidden", "a/b", "..", "a\x00b", "/abs", "x" * 5000, "²", "0"]
WRONG_VALUES = [None, True, 1.5, 7, "text", [], {}]
JSON_TYPES = {"object": dict, "array": list, "string": str, "boolean": bool, "null": type(None)}


def _is(v, t):
    if t == "integer":
        return isinstance(v, int) and not isinstance(v, bool)
    if t == "number":
        return isinstance(v, (int, float)) and not isinstance(v, bool)
    return isinstance(v, JSON_TYPES[t])


def _breakers(value, schema):
    """(rule, broken value) for each constraint of ``schema`` that ``value`` can be made to break."""
    out = []
    types = schema.get("type")
    if types is not None:
        types = [types] if isinstance(types, str) else types
        out += [("type", v) for v in WRONG_VALUES if not any(_is(v, t) for t in types)][:1]
    if "const" in schema:
        out.append(("const", "not " + str(schema["const"])))
    if "enum" in schema:
        out.append(("enum", "none of these"))
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        for rule, delta in (("minimum", -1), ("maximum", 1), ("exclusiveMinimum", 0), ("exclusiveMaximum", 0)):
            if rule in schema:
                out.append((rule, schema[rule] + delta))
    if isinstance(value, list):
        if schema.get("minItems", 0) >= 1:
            out.append(("minItems", value[:schema["minItems"] - 1]))
        if "maxItems" in schema and value:
            out.append(("maxItems", value + [value[-1]] * (schema["maxItems"] + 1 - len(value))))
    if isinstance(value, str):
        if schema.get("minLength", 0) >= 1:
            out.append(("minLength", ""))
        if "maxLength" in schema:
            out.append(("maxLength", "x" * (schema["maxLength"] + 1)))
        if "pattern" in schema:
            bad = next(s for s in BAD_STRINGS if not re.search(schema["pattern"], s))
            out.append(("pattern", bad))
    return out


def _rules(doc, schema, where=()):
    """(location, rule, edit) for every rule the schema applies somewhere in ``doc``."""
    if "anyOf" in schema or "oneOf" in schema:
        return  # a value may satisfy another alternative
    for rule, bad in _breakers(doc, schema):
        yield where, rule, ("set", bad)
    if isinstance(doc, dict):
        props = schema.get("properties", {})
        for k in schema.get("required", []):
            if k in doc:
                yield (*where, k), "required", ("delete", None)
        if schema.get("additionalProperties") is False:
            yield (*where, "zz_unknown"), "additionalProperties", ("add", 1)
        if "pattern" in schema.get("propertyNames", {}):
            bad = next(s for s in BAD_STRINGS if not re.search(schema["propertyNames"]["pattern"], s))
            yield (*where, bad), "propertyNames", ("add", next(iter(doc.values()), 1))
        for k, v in doc.items():
            if k in props:
                yield from _rules(v, props[k], (*where, k))
            else:
                sub = next((s for p, s in schema.get("patternProperties", {}).items() if re.search(p, k)), None)
                if sub is None and isinstance(schema.get("additionalProperties"), dict):
                    sub = schema["additionalProperties"]
                if sub is not None:
                    yield from _rules(v, sub, (*where, k))
    elif isinstance(doc, list) and isinstance(schema.get("items"), dict) and doc:
        yield from _rules(doc[0], schema["items"], (*where, 0))


def _edited(doc, where, edit):
    doc = copy.deepcopy(doc)
    parent = doc
    for p in where[:-1]:
        parent = parent[p]
    action, value = edit
    if action == "delete":
        del parent[where[-1]]
    elif action == "set" and not where:
        return value
    else:
        parent[where[-1]] = value
    return doc


def _bases():
    demo = json.loads((DEMO_PACKAGE / "manifest.json").read_text(encoding="utf-8"))
    small = manifest_dict(lateral=(1.0,), sun=(0.3, 0.2, 0.9), harmonize=True)
    small["ground_truth"] = TRAFFIC_GT
    small["masks"] = {"entries": [{"camera": "front", "frame": 0, "actor": "car_0", "amodal": "m.png",
                                   "visible": "v.png"}],
                      "id_maps": [{"camera": "front", "frame": 0, "path": "ids.png", "ids": {"1": "car_0"}}]}
    small["source"] = {"format": "colmap", "path": "sparse/0", "scale": 0.37,
                       "transform": [[0.37, 0, 0, 1], [0, 0.37, 0, 2], [0, 0, 0.37, 3], [0, 0, 0, 1]]}
    return {"demo": demo, "small": json.loads(json.dumps(small))}  # JSON's own types (lists, not tuples)


CASES = [(name, where, rule, edit) for name, doc in _bases().items()
         for where, rule, edit in _rules(doc, manifest_schema())]


def test_the_bases_load_and_reach_every_kind_of_rule(tmp_path):
    for doc in _bases().values():
        parse_manifest(doc, tmp_path / "manifest.json")
    kinds = {rule for _, _, rule, _ in CASES}
    assert {"type", "const", "enum", "minimum", "exclusiveMinimum", "maximum", "minItems", "maxItems", "minLength",
            "maxLength", "pattern", "required", "additionalProperties", "propertyNames"} <= kinds, kinds
    assert len(CASES) > 300


@pytest.mark.parametrize("base, where, rule, edit", CASES,
                         ids=[f"{b}:{field_path(w)}:{r}" for b, w, r, _ in CASES])
def test_each_rule_broken_is_refused_naming_the_field(tmp_path, base, where, rule, edit):
    doc = _edited(_bases()[base], where, edit)
    with pytest.raises(ManifestError) as exc:
        parse_manifest(doc, tmp_path / "manifest.json")
    at = field_path(where[:-1] if rule == "propertyNames" else where)
    assert (exc.value.field or "").startswith(at if where else ""), (exc.value.field, at, str(exc.value))


def test_the_command_line_exits_2_with_the_suggestion(tmp_path, capsys):
    doc = _bases()["small"]
    doc["effects"]["harmonise"] = doc["effects"].pop("harmonize")
    path = tmp_path / "manifest.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    assert main(["validate", str(path), "--no-files"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "effects.harmonise: unknown field; did you mean 'harmonize'?" in err


def test_without_jsonschema_the_reader_still_checks_what_it_reads(tmp_path, monkeypatch):
    """Blender's Python has no jsonschema: the add-on's loads keep the reader's own checks."""
    from symdrive_core.scene import schema

    monkeypatch.setattr(schema, "_validator", lambda: None)
    doc = _bases()["small"]
    parse_manifest(doc, tmp_path / "manifest.json")
    doc["cameras"][0]["width"] = "wide"
    with pytest.raises(ManifestError, match=r"cameras\[0\]\.width"):
        parse_manifest(doc, tmp_path / "manifest.json")
