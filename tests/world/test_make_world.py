"""The generator end to end at a tiny size (Cycles renders six 48x27 frames and their lane masks)."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from symdrive_core.io.images import read_image, read_mask
from symdrive_core.io.points import read_points
from symdrive_core.scene import check_files, load_manifest

pytest.importorskip("bpy")
pytestmark = [pytest.mark.blender, pytest.mark.slow]  # ~15-35 s: Blender start + Cycles

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "make_world.py"


def _env() -> dict[str, str]:
    """The subprocess's environment: this checkout's ``symdrive_core`` first (an editable install
    elsewhere, or none, would otherwise decide), then the inherited ``PYTHONPATH`` (which may
    select the ``bpy`` under test)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    return env


@pytest.fixture(scope="module")
def package(tmp_path_factory):
    out = tmp_path_factory.mktemp("world") / "pkg"
    subprocess.run([sys.executable, str(SCRIPT), "--out", str(out), "--width", "48", "--height", "27",
                    "--frames", "3", "--samples", "4", "--offsets", "1.0", "--lateral-every", "2",
                    "--holdout-every", "3", "--placements", "1", "--points", "3000", "--asset-splats", "500"],
                   check=True, capture_output=True, env=_env())
    return load_manifest(out)


def test_package_is_valid_and_complete(package):
    check_files(package)
    gt = package.ground_truth
    assert gt["train_frames"] == [0, 2] and gt["heldout_frames"] == [1]
    assert set(gt["road"]) == {"centerline", "lanes", "lane_width"}
    assert gt["road"]["lanes"] == 2 and len(gt["road"]["centerline"][0]) == 3
    assert [e["offset_m"] for e in gt["lateral"]] == [1.0]
    assert sorted(gt["lateral"][0]["frames"]) == ["0", "2"]
    assert package.effects.sun_direction is not None and package.effects.sun_direction[2] < 0
    for rel in [f for e in gt["lateral"] for f in e["frames"].values()]:
        assert read_image(package.resolve(rel)).shape == (27, 48, 3)


def test_package_was_rendered_by_this_blender(package):
    """The generator runs as a subprocess with ``sys.executable``: it must find the same ``bpy``
    as this process (so a test run against a given Blender renders with that Blender)."""
    import bpy

    assert package.ground_truth["generator"]["blender"] == bpy.app.version_string


def test_depth_is_opencv_z_of_the_road(package):
    """Bottom-centre pixels see the flat road (z = 0): their Cycles depth must equal the
    z-depth of that ray's hit with the ground, from the manifest's K and camera pose."""
    cam = package.cameras[0]
    cf = cam.frames[0]
    depth = read_image(package.resolve(cf.depth))[:, :, 0]
    K, c2w = cf.K, cf.camera_to_world
    for v in (cam.height - 1, cam.height - 3):
        u = cam.width // 2
        ray = np.array([(u + 0.5 - K[0, 2]) / K[0, 0], (v + 0.5 - K[1, 2]) / K[1, 1], 1.0])
        d_world = c2w[:3, :3] @ ray
        z_expected = -c2w[2, 3] / d_world[2]  # ray parameter where world z = 0 (= camera z-depth)
        assert depth[v, u] == pytest.approx(z_expected, rel=0.03)
    assert (depth[0] == 0).any()  # the top row sees sky somewhere: stored as 0


def test_insertion_has_mask_shadow_and_matches_the_asset(package):
    ins = package.ground_truth["insertion"][0]
    mask = read_mask(package.resolve(ins["mask"])) > 0.5
    shadow = read_mask(package.resolve(ins["shadow_mask"])) > 0.5
    assert mask.sum() == ins["mask_pixels"] > 0 and shadow.sum() == ins["shadow_pixels"] > 0
    assert not (mask & shadow).any()
    with_car = read_image(package.resolve(ins["with"]), channels=3)
    without = read_image(package.resolve(ins["without"]), channels=3)
    assert np.abs(with_car - without)[mask].mean() > 0.05
    actor = package.actor(ins["actor"])
    assert actor.kind == "inserted" and actor.poses[ins["frame"]] is not None
    assert sum(p is not None for p in actor.poses) == 1
    assert actor.poses[ins["frame"]].translation[2] == pytest.approx(actor.wlh[2] / 2)


def test_assets_follow_the_3drealcar_frame(package):
    for kind in ("sedan", "suv", "hatchback"):
        folder = package.root / "assets" / kind
        info = json.loads((folder / "wlh.json").read_text())
        verts = np.array([[float(x) for x in ln.split()[1:]] for ln in (folder / "mesh.obj").read_text().splitlines()
                          if ln.startswith("v ")])
        lo, hi = verts.min(0), verts.max(0)
        assert np.allclose(lo + hi, 0, atol=1e-5)  # origin at the box centre
        w, l, h = info["wlh"]
        assert np.allclose(hi - lo, [l, w, h], atol=1e-3) and l > w  # X along the length


def test_point_cloud_lies_near_the_depth_maps(package):
    pts, cols = read_points(package.resolve(package.background_points))
    assert len(pts) > 100 and cols.min() >= 0 and cols.max() <= 1
    assert np.abs(pts[:, 2]).max() < 40  # on the scene, not on the sky


def test_every_view_has_a_lane_mask_on_its_painted_lines(package):
    lanes = package.ground_truth["lanes"]
    assert sorted(lanes["recorded"]) == ["0", "1", "2"]
    assert [(e["offset_m"], sorted(e["frames"])) for e in lanes["lateral"]] == [(1.0, ["0", "2"])]
    cam = package.cameras[0]
    for key, rel in lanes["recorded"].items():
        mask = read_mask(package.resolve(rel)) > 0.5
        value = read_image(package.resolve(cam.frames[int(key)].image), channels=3).max(axis=2)
        assert mask.shape == (27, 48) and mask.any()
        assert value[mask].mean() > value[mask.shape[0] // 2:].mean() + 0.1  # paint outshines the lower half


def test_lane_masks_of_an_existing_package_match_make_worlds(package, tmp_path):
    """``make_lane_masks.py`` rebuilds the street of a package and writes the same masks."""
    copy = tmp_path / "pkg"
    shutil.copytree(package.root, copy)
    shutil.rmtree(copy / "gt" / "lanes")
    data = json.loads((copy / "manifest.json").read_text(encoding="utf-8"))
    written = data["ground_truth"].pop("lanes")
    (copy / "manifest.json").write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    subprocess.run([sys.executable, str(ROOT / "scripts" / "make_lane_masks.py"), str(copy)],
                   check=True, capture_output=True, env=_env())
    again = load_manifest(copy).ground_truth["lanes"]
    assert again == written
    for rel in [*written["recorded"].values(), *[f for e in written["lateral"] for f in e["frames"].values()]]:
        assert np.array_equal(read_mask(copy / rel), read_mask(package.resolve(rel)))
