"""The manifest's ``source`` block: written by the importers, checked by the loader and the schema."""

from __future__ import annotations

import json

import jsonschema
import numpy as np
import pytest

from symdrive_core.scene import load_manifest
from symdrive_core.scene.manifest import SCHEMA_PATH, ManifestError, parse_manifest

from ..conftest import manifest_dict


def test_source_round_trips_and_matches_the_schema(tmp_path):
    d = manifest_dict()
    T = np.diag([2.0, 2.0, 2.0, 1.0])
    T[:3, 3] = [1, 2, 3]
    d["source"] = {"format": "colmap", "path": "/data/sparse/0", "transform": T.tolist(), "scale": 2.0}
    m = parse_manifest(d, tmp_path / "manifest.json")
    assert m.source["transform"] == T.tolist()
    out = m.to_json()
    assert out["source"] == d["source"]
    jsonschema.validate(out, json.loads(SCHEMA_PATH.read_text()))
    m.save(tmp_path / "manifest.json")
    assert load_manifest(tmp_path).source == d["source"]


@pytest.mark.parametrize("bad", [np.diag([1.0, 1.0, -1.0, 1.0]), np.diag([1.0, 2.0, 1.0, 1.0]),
                                 np.full((4, 4), np.nan)])
def test_source_transform_must_be_a_similarity(tmp_path, bad):
    d = manifest_dict()
    d["source"] = {"transform": [[None if np.isnan(v) else float(v) for v in row] for row in bad]}
    with pytest.raises(ManifestError, match="source.transform"):
        parse_manifest(d, tmp_path / "manifest.json")
