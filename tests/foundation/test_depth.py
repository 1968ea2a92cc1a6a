"""Depth maps' declared meaning of 0 (``cameras[].depth_zero``) and the one decoded form readers see."""

import json

import jsonschema
import numpy as np
import pytest

from symdrive_core.io.images import write_image
from symdrive_core.scene import ManifestError, load_manifest, parse_manifest, schema
from symdrive_core.scene.depth import decode_depth, is_sky, measured, read_depth
from symdrive_core.scene.manifest import SCHEMA_PATH
from tests.conftest import manifest_dict

STORED = np.array([[0.0, -1.0, np.nan, np.inf, -np.inf, 2.5]], np.float32)


@pytest.mark.parametrize("zero, expected", [
    ("sky", [np.inf, np.inf, np.nan, np.inf, np.inf, 2.5]),  # dense maps: nothing measured is sky
    ("unmeasured", [np.nan, np.nan, np.nan, np.inf, np.nan, 2.5]),  # sparse maps: +inf is still sky
])
def test_stored_zero_means_what_the_camera_declares(zero, expected):
    d = decode_depth(STORED, zero)
    np.testing.assert_array_equal(d[0], np.array(expected, np.float32))
    assert measured(d).tolist() == [[False] * 5 + [True]]
    assert is_sky(d).sum() == (4 if zero == "sky" else 1)
    with pytest.raises(ValueError, match="depth_zero"):
        decode_depth(STORED, "none")


def test_packages_without_the_field_keep_zero_as_sky(tmp_path):
    d = manifest_dict(n_frames=2, width=6, height=1)
    d["cameras"][0]["frames"][1]["depth"] = "d.exr"
    write_image(tmp_path / "d.exr", STORED, dtype="float")
    m = parse_manifest(d, tmp_path / "manifest.json")
    assert m.cameras[0].depth_zero == "sky" and "depth_zero" not in m.to_json()["cameras"][0]
    assert is_sky(read_depth(m, m.cameras[0], 1)).sum() == 4
    assert read_depth(m, m.cameras[0], 0) is None


def test_unmeasured_round_trips_and_satisfies_the_schema(tmp_path):
    d = manifest_dict(n_frames=2)
    d["cameras"][0]["depth_zero"] = "unmeasured"
    m = parse_manifest(d, tmp_path / "manifest.json")
    assert m.cameras[0].depth_zero == "unmeasured"
    m.save()
    saved = json.loads((tmp_path / "manifest.json").read_text())
    assert saved["cameras"][0]["depth_zero"] == "unmeasured"
    jsonschema.validate(saved, json.loads(SCHEMA_PATH.read_text()))
    assert load_manifest(tmp_path).cameras[0].depth_zero == "unmeasured"


@pytest.mark.parametrize("with_jsonschema", [True, False])
def test_an_unknown_meaning_is_refused_naming_the_field(tmp_path, monkeypatch, with_jsonschema):
    if not with_jsonschema:  # Blender's Python: the reader's own check
        monkeypatch.setattr(schema, "_validator", lambda: None)
    d = manifest_dict(n_frames=2)
    d["cameras"][0]["depth_zero"] = "none"
    with pytest.raises(ManifestError) as err:
        parse_manifest(d, tmp_path / "manifest.json")
    assert err.value.field == "cameras[0].depth_zero"
