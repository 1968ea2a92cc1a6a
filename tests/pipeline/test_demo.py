"""The README's main job: ``symdrive demo --quick`` end to end on the built-in world."""

import json

import pytest

from symdrive_core.cli import main
from symdrive_core.io.images import read_image


def test_quick_demo_end_to_end(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--quick", "--quiet", "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    ran = {s["name"] for s in report["stages"] if s["ran"]}
    assert {"render", "restore", "harmonize", "finetune", "evaluate"} <= ran
    methods = {(r["offset_m"], r["method"]) for r in report["metrics"]["lateral"]}
    assert {(3.0, "raw_3dgs"), (3.0, "ar_d0.5"), (3.0, "geo_ar_d1.0"), (1.0, "single_view")} <= methods
    assert all(r["psnr_cc"] >= r["psnr"] for r in report["metrics"]["lateral"])  # the colour fit, every row
    assert {r["method"] for r in report["metrics"]["insertion"]} == {
        "naive", "color_transfer", "cast_shadow", "harmonized", "finetuned", "finetuned_shadow"}
    assert len(list((out / "shadows").rglob("*.png"))) == 1  # the sunny street: the window's frame 12 has a car
    assert 25.0 < report["metrics"]["reconstruction"]["psnr_heldout"] < 60.0
    md = (out / "report.md").read_text()
    assert "| PSNR | PSNR-cc | SSIM |" in md
    for fig in ("lateral.png", "lateral_psnr.png", "insertion.png", "trajectory.png"):
        assert f"figures/{fig}" in md and read_image(out / "figures" / fig).shape[0] > 100
    assert len(list((out / "trajectory").glob("*.png"))) == 30
    assert "report.md" in capsys.readouterr().out


@pytest.mark.slow  # the full demo: three frames at every offset, refinement on (about 20 minutes on 2 cores)
def test_full_demo_end_to_end(tmp_path):
    out = tmp_path / "demo"
    assert main(["demo", "--quiet", "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["demo_mode"] == "full"
    ran = {s["name"] for s in report["stages"] if s["ran"]}
    assert {"render", "restore", "refine", "harmonize", "finetune", "evaluate"} <= ran
    rows = report["metrics"]["lateral"]
    assert {r["method"] for r in rows} >= {"raw_3dgs", "single_view", "ar_d0.5", "geo_ar_d1.0", "refined"}
    assert {r["offset_m"] for r in rows if r["method"] == "refined"} == {-3.0, -2.0, -1.5, -1.0, -0.5,
                                                                         0.5, 1.0, 1.5, 2.0, 3.0}
