"""A drive with poses and images but no points: the import triangulates points from the images with
the poses fixed, and ``symdrive reconstruct`` starts from them."""

from __future__ import annotations

import json

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.importers.similarity import apply_points
from symdrive_core.io.images import read_image
from symdrive_core.io.points import read_points
from symdrive_core.scene import load_manifest

from .demo_formats import CAMERA_HEIGHT, DEMO, demo_world, write_nerfstudio
from .test_roundtrip import align_yaw

pytest.importorskip("pycolmap")


def depth_errors(points: np.ndarray) -> np.ndarray:
    """Per point seen by a demo frame: the smallest relative difference between its depth and the
    rendered depth at its pixel over the frames that see it (a frame where it is hidden disagrees)."""
    demo = load_manifest(DEMO)
    cam = demo.cameras[0]
    best = np.full(len(points), np.inf)
    for f in cam.frames:
        x = points @ f.world_to_camera[:3, :3].T + f.world_to_camera[:3, 3]
        uv = x @ f.K.T
        z = x[:, 2]
        ok = z > 0.1
        u = np.floor(uv[:, 0] / np.where(ok, z, 1.0)).astype(int)
        v = np.floor(uv[:, 1] / np.where(ok, z, 1.0)).astype(int)
        ok &= (u >= 0) & (u < cam.width) & (v >= 0) & (v < cam.height)
        depth = read_image(demo.resolve(f.depth))[..., 0]
        d = np.zeros(len(points))
        d[ok] = depth[v[ok], u[ok]]
        ok &= d > 0
        best[ok] = np.minimum(best[ok], np.abs(z[ok] - d[ok]) / d[ok])
    return best[np.isfinite(best)]


def test_poses_only_demo_street_triangulates_and_reconstructs(tmp_path, capsys):
    world = demo_world(seed=6, max_splats=2000)
    tj = write_nerfstudio(world, tmp_path / "ns", with_points=False)
    assert "ply_file_path" not in json.loads(tj.read_text())
    pkg = tmp_path / "pkg"
    # the demo's road has little texture, so few road points: the ground is placed by the poses'
    # known up, the camera height and the scale
    up = world.S[:3, :3] @ [0.0, 0.0, 1.0]
    assert main(["import", "nerfstudio", str(tj), "--out", str(pkg), "--camera-height", str(CAMERA_HEIGHT),
                 "--scale", repr(1 / 0.37), "--up=" + ",".join(f"{float(v)!r}" for v in up), "--heldout-every", "5",
                 "--copy-images", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "triangulated" in out
    assert not list(tmp_path.glob(".pkg.*")), "the triangulation's work folder is removed"
    m = load_manifest(pkg)
    tri = m.source["triangulated"]
    # the 24 training frames' images only: the 6 held out never reach the start
    assert tri["points"] >= 300 and tri["images"] == 24 and tri["mean_reprojection_error_px"] < 1.0, tri
    pts, cols = read_points(m.resolve(m.background_points))
    assert len(pts) == tri["points"] and cols.std() > 0.01  # coloured from the images
    c2w = np.stack([f.camera_to_world for f in m.cameras[0].frames])
    np.testing.assert_allclose(c2w[:, 2, 3], world.c2w_demo[:, 2, 3], atol=1e-6)  # the ground placed right
    M = align_yaw(c2w[:, :3, 3], world.c2w_demo[:, :3, 3])
    err = depth_errors(apply_points(M, pts.astype(np.float64)))
    print(f"{len(pts)} points, {len(err)} seen; depth error median {np.median(err):.3f}, "
          f"75th percentile {np.percentile(err, 75):.3f}")
    assert len(err) > 0.9 * len(pts)
    assert np.median(err) < 0.05 and np.percentile(err, 75) < 0.15
    assert main(["reconstruct", str(pkg), "--iters", "5", "--out", str(tmp_path / "rec")]) == 0
    metrics = json.loads((tmp_path / "rec" / "metrics.json").read_text())
    assert metrics["gaussians"] >= tri["points"] and metrics["heldout"]["frames"] == 6
