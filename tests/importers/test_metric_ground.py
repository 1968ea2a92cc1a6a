"""Metric poses imported with the right camera height keep their scale, and every importer finds the
same ground: a curved metric drive with kerbs, parked cars and facades, through COLMAP and nerfstudio."""

from __future__ import annotations

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.scene import load_manifest

from .curved_street import CAMERA_HEIGHT, curved_world
from .demo_formats import write_colmap, write_nerfstudio

pytest.importorskip("pycolmap")


def _import(args, out, capsys):
    rc = main(["import", *args, "--out", str(out), "--camera-height", str(CAMERA_HEIGHT), "--quiet"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    return load_manifest(out, allow_external=True).source, captured


@pytest.mark.parametrize("seed", [0, 3])
def test_curved_metric_drive_same_plane_and_scale_through_colmap_and_nerfstudio(seed, tmp_path, capsys):
    world, _ = curved_world(tmp_path, seed=seed)
    colmap, out_c = _import(["colmap", str(write_colmap(world, tmp_path / "sparse"))], tmp_path / "c", capsys)
    ns, out_n = _import(["nerfstudio", str(write_nerfstudio(world, tmp_path / "ns"))], tmp_path / "n", capsys)
    for src in (colmap, ns):
        assert abs(src["scale"] - 1.0) < 0.005, src["scale"]  # the poses were metric
        q = src["ground_fit"]
        assert q["weak"] == [] and q["inliers"] >= 50 and q["inlier_fraction"] > 0.8, q
        assert q["residual_rms_m"] < 0.02 and q["camera_height_spread_m"] < 0.02, q
        true_up = world.S[:3, :3] @ [0.0, 0.0, 1.0]
        assert np.degrees(np.arccos(min(1.0, np.dot(src["ground_normal"], true_up)))) < 0.1
    # one fit: the same plane (normal and height) from both importers
    assert np.dot(colmap["ground_normal"], ns["ground_normal"]) > np.cos(1e-3)
    assert abs(colmap["camera_height_source_units"] / ns["camera_height_source_units"] - 1) < 1e-3
    assert abs(colmap["scale"] / ns["scale"] - 1) < 1e-3
    np.testing.assert_allclose(colmap["transform"], ns["transform"], atol=1e-3 * 500)
    for captured in (out_c, out_n):
        assert "points under the camera path on the plane" in captured.out
        assert "warning" not in captured.err


def test_metric_poses_with_scale_place_the_ground_and_a_mismatch_warns(tmp_path, capsys):
    world, _ = curved_world(tmp_path, seed=1)
    model = str(write_colmap(world, tmp_path / "sparse"))
    src, captured = _import(["colmap", model, "--scale", "1"], tmp_path / "a", capsys)
    assert src["scale"] == 1.0 and abs(src["camera_height_m"] - CAMERA_HEIGHT) < 1e-9
    assert abs(src["ground_fit"]["fitted_camera_height_m"] - CAMERA_HEIGHT) < 0.01
    assert "warning" not in captured.err
    # the wrong unit (centimetres said to be metres): the placed ground is far from the fitted one
    src, captured = _import(["colmap", model, "--scale", "0.01"], tmp_path / "b", capsys)
    assert src["camera_height_m"] == pytest.approx(CAMERA_HEIGHT)
    assert src["ground_fit"]["weak"] and "fitted plane" in src["ground_fit"]["weak"][0]
    assert captured.err.startswith("warning: weak ground fit:") and len(captured.err.splitlines()) == 1


def test_poses_only_without_images_up_and_camera_height_place_the_ground(tmp_path, capsys):
    """No points and no images to triangulate from: the ground lies --camera-height below the
    cameras' median height, along --up, and the poses are taken as metric."""
    world, _ = curved_world(tmp_path, seed=2)
    model = write_colmap(world, tmp_path / "sparse", with_points=False)
    up = world.S[:3, :3] @ [0.0, 0.0, 1.0]
    out = tmp_path / "pkg"
    args = ["import", "colmap", str(model), "--out", str(out), "--camera-height", str(CAMERA_HEIGHT)]
    assert main([*args, "--up=" + ",".join(f"{v:.12g}" for v in up)]) == 0  # '=': the vector may start with '-'
    m = load_manifest(out)
    z = np.array([f.camera_to_world[2, 3] for f in m.cameras[0].frames])
    assert m.source["scale"] == 1.0 and abs(np.median(z) - CAMERA_HEIGHT) < 1e-9
    np.testing.assert_allclose(z, world.c2w_demo[:, 2, 3] - np.median(world.c2w_demo[:, 2, 3]) + CAMERA_HEIGHT,
                               atol=1e-6)
    capsys.readouterr()
    assert main([*args[:-2], "--force"]) == 2  # no points, no images, no --camera-height: nothing to place it by
    err = capsys.readouterr().err
    assert "--up" in err and len(err.strip().splitlines()) == 1


def test_images_that_triangulate_to_no_points_are_refused_unless_the_ground_is_placed(tmp_path, capsys):
    """Featureless images: triangulation finds nothing, so nothing places the ground (exit 2,
    one line) unless --up and --camera-height do, and then the package is said to have no points."""
    from symdrive_core.io.images import write_image

    world, _ = curved_world(tmp_path, seed=2)
    model = write_colmap(world, tmp_path / "sparse", with_points=False)
    for name in world.names:  # new files: the world's images are links to the demo's
        write_image(tmp_path / "images" / name, np.full((world.height, world.width, 3), 0.5, np.float32))
    out = tmp_path / "pkg"
    args = ["import", "colmap", str(model), "--images", str(tmp_path / "images"), "--out", str(out), "--quiet"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "points: no points triangulated from the images" in err, err
    assert not out.exists()
    up = world.S[:3, :3] @ [0.0, 0.0, 1.0]
    assert main([*args, "--camera-height", str(CAMERA_HEIGHT), "--up=" + ",".join(f"{v:.12g}" for v in up)]) == 0
    assert "warning: the package has no points" in capsys.readouterr().err
