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


def test_ground_fit_and_triangulation_records_match_the_schema(tmp_path):
    d = manifest_dict()
    d["source"] = {"format": "nerfstudio", "transform": np.eye(4).tolist(), "scale": 1.0,
                   "ground_fit": {"corridor_points": 120, "inliers": 110, "inlier_fraction": 0.9167,
                                  "residual_rms_m": 0.01, "camera_height_spread_m": 0.008, "weak": [],
                                  "fitted_camera_height_m": 1.65},
                   "triangulated": {"points": 700, "images": 30, "mean_track_length": 6.8,
                                    "mean_reprojection_error_px": 0.46}}
    m = parse_manifest(d, tmp_path / "manifest.json")
    assert m.to_json()["source"] == d["source"]
    d["source"]["ground_fit"]["inlier_fraction"] = 1.5
    with pytest.raises(ManifestError, match="source.ground_fit.inlier_fraction"):
        parse_manifest(d, tmp_path / "manifest.json")
    d["source"]["ground_fit"]["inlier_fraction"] = 0.5
    d["source"]["triangulated"]["points"] = -1
    with pytest.raises(ManifestError, match="triangulated"):
        parse_manifest(d, tmp_path / "manifest.json")
