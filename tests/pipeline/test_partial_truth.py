"""Real drives are partial: SfM finds no road under some cameras, and a stereo rig's lateral truth
sits at its baseline only. Restoring and scoring go on with what the package has, and say so."""

import json

import numpy as np

from symdrive_core.cli import main
from symdrive_core.io.ply import write_splats
from symdrive_core.io.points import read_points, write_points
from tests.optim.conftest import write_package

FAST = ["--steps", "2", "--n-start", "1", "--threads", "1"]


def _package_without_road_points(root):
    """The synthetic wall-and-floor package (truth at -0.5 and +0.5 m), its SfM points keeping
    nothing of the floor near the camera path, and its true Gaussians as the reconstruction."""
    root, truth = write_package(root)
    points, colors = read_points(root / "points.ply")
    keep = ~((points[:, 2] < 0.4) & (points[:, 1] < 3.0))
    write_points(root / "points.ply", points[keep], colors[keep])
    write_splats(root / "recon.ply", truth)
    return root


def test_guided_evaluation_fits_the_ground_to_the_splats_where_the_points_have_none(tmp_path):
    root = _package_without_road_points(tmp_path / "pkg")
    out = tmp_path / "eval"
    assert main(["restore", str(root), "--gaussians", str(root / "recon.ply"), *FAST, "--out", str(out),
                 "--evaluate", "--frames", "0,4", "--methods", "warp,geo_ar_d1.0", "--quiet"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics["ground"]["planes"]) == {"splats"}
    assert all("points under the camera path" in w["why"] for w in metrics["ground"]["other_than_points"])
    rows = {(r["offset_m"], r["method"]) for r in metrics["lateral"]}
    assert rows == {(o, m) for o in (-0.5, 0.5) for m in ("raw_3dgs", "warp", "geo_ar_d1.0")}


def test_run_restores_offsets_without_truth_and_scores_the_ones_with(tmp_path):
    root, truth = write_package(tmp_path / "pkg")
    write_splats(root / "recon.ply", truth)
    manifest = json.loads((root / "manifest.json").read_text())
    manifest["background"]["splats"] = "recon.ply"
    (root / "manifest.json").write_text(json.dumps(manifest))

    out = tmp_path / "run"
    assert main(["run", str(root), "--out", str(out), "--frames", "2", "--offsets", "1", "--no-refine",
                 "--no-adapt", "--quiet"]) == 0
    report = json.loads((out / "report.json").read_text())
    restore = next(s for s in report["stages"] if s["name"] == "restore")
    assert restore["views_restored"] == 2 and "no lateral truth at -1, +1 m" in restore["lateral_not_scored"]
    assert "+0.5" in restore["lateral_not_scored"] and not report["metrics"].get("lateral")
    assert sorted(p.parent.name for p in (out / "restore").rglob("*.png")) == ["+1", "-1"]

    out = tmp_path / "run-both"  # an offset with truth next to one without: the first is scored
    assert main(["run", str(root), "--out", str(out), "--frames", "2", "--offsets", "0.5,1", "--no-refine",
                 "--no-adapt", "--quiet"]) == 0
    report = json.loads((out / "report.json").read_text())
    restore = next(s for s in report["stages"] if s["name"] == "restore")
    assert restore["views_restored"] == 4 and "no lateral truth at -1, +1 m" in restore["lateral_not_scored"]
    assert {r["offset_m"] for r in report["metrics"]["lateral"]} == {-0.5, 0.5}
    assert np.isfinite([r["psnr"] for r in report["metrics"]["lateral"]]).all()
