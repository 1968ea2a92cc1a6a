"""The accuracy-vs-time report: real measurements, Pareto marks, and the files it writes."""

import json

import pytest

from symdrive_core.bench.accuracy_time import Setting, format_table, run_settings, write_outputs
from symdrive_core.bench.knobs import Budget, lateral_quality, renderer_settings, shadow_settings, spread
from symdrive_core.cli import main
from symdrive_core.io.images import read_image
from symdrive_core.io.ply import read_splats
from symdrive_core.scene import load_manifest
from symdrive_core.world.demo import DEMO_PACKAGE


def test_pareto_marks_and_outputs(tmp_path):
    measured = {"a": (1.0, 20.0), "b": (2.0, 25.0), "c": (3.0, 24.0)}  # (seconds, PSNR)
    settings = [Setting("k", v, v == "b", lambda q=q: {"seconds": q[0], "psnr": q[1]}) for v, q in measured.items()]
    rows = run_settings(settings, progress=False)
    assert [r["pareto"] for r in rows] == [True, True, False]  # c is slower and worse than b
    paths = write_outputs(rows, tmp_path, {"k": "why b"})
    data = json.loads(paths["json"].read_text())
    assert data["rows"] == rows and data["defaults"] == {"k": "why b"}
    assert "**b** (default)" in paths["md"].read_text() and "why b" in paths["md"].read_text()
    assert read_image(paths["png"]).ndim == 3


def test_lane_iou_and_psnr_cc_are_columns_where_the_rows_carry_them():
    rows = [{"psnr": 20.0, "ssim": 0.5, "psnr_cc": 21.0, "lane_iou": 10.0},
            {"psnr": 22.0, "ssim": 0.7, "psnr_cc": 24.0, "lane_iou": 20.0}]
    assert lateral_quality(rows) == pytest.approx({"psnr": 21.0, "ssim": 0.6, "psnr_cc": 22.5, "lane_iou": 15.0})
    rows[1].pop("lane_iou")  # a package without lane masks
    assert "lane_iou" not in lateral_quality(rows)
    settings = [Setting("d", "0.5 m", True, lambda: {"seconds": 1.0, "psnr": 21.0, "psnr_cc": 22.5, "lane_iou": 3.44}),
                Setting("aa", "off", True, lambda: {"seconds": 1.0, "psnr": 30.0})]
    table = format_table(run_settings(settings, progress=False)).splitlines()
    assert "| PSNR-cc (dB) |" in table[0] and "| lane IoU |" in table[0]
    assert "| 21.00 | 22.50 |" in table[2] and "| 3.4 |" in table[2] and "| 30.00 |  | nan |  |" in table[3]


def test_spread_picks_inside_the_sequence():
    assert spread([0, 2, 4, 6, 8], 1) == [4]
    assert spread([0, 2, 4, 6, 8], 2) == [2, 6]
    assert spread([1, 2], 5) == [1, 2]


def test_renderer_knobs_measured_against_cycles():
    m = load_manifest(DEMO_PACKAGE)
    rows = run_settings(renderer_settings(m, read_splats(m.resolve(m.background_splats)), Budget(render_frames=1)),
                        progress=False)
    by = {(r["knob"], r["value"]): r for r in rows}
    assert {r["knob"] for r in rows} == {"antialiasing", "extent", "SH degree", "alpha threshold", "precision",
                                         "resolution"}
    assert all(r["seconds"] > 0 and 10.0 < r["psnr"] < 60.0 for r in rows)
    # float64 and float32 agree to far below what PSNR resolves; half resolution loses detail.
    assert abs(by["precision", "float64"]["psnr"] - by["precision", "float32"]["psnr"]) < 0.01
    assert by["resolution", "0.5x, upsampled"]["psnr"] < by["resolution", "1x, upsampled"]["psnr"] - 1.0
    assert sum(r["default"] for r in rows if r["knob"] == "SH degree") == 1


@pytest.mark.slow
def test_accuracy_time_command_quick(tmp_path, capsys):
    assert main(["bench", "accuracy-time", "--quick", "--quiet", "--out", str(tmp_path)]) == 0
    rows = json.loads((tmp_path / "accuracy_time.json").read_text())["rows"]
    knobs = {r["knob"] for r in rows}
    assert {"sampler steps", "start noise", "N_start of 50 steps, 1 sample", "AR step d", "AR step d, guided",
            "alpha threshold", "fine-tune iterations",
            "antialiasing", "cast shadow"} <= knobs
    assert all(sum(r["default"] for r in rows if r["knob"] == k) == 1 for k in knobs)
    assert (tmp_path / "pareto.png").exists()


def test_cast_shadow_knob_measured_against_cycles():
    m = load_manifest(DEMO_PACKAGE)
    rows = run_settings(shadow_settings(m, read_splats(m.resolve(m.background_splats)), Budget(placements=1)),
                        progress=False)
    by = {r["value"]: r for r in rows}
    assert list(by)[0] == "off" and sum(r["default"] for r in rows) == 1 and by["shade keeps 0.40"]["default"]
    assert all(r["seconds"] > 0 and 10.0 < r["psnr"] < 40.0 for r in rows)
    # the sunny street: its car's shadow at any plausible ratio beats no shadow
    assert min(r["psnr"] for r in rows if r["value"] != "off") > by["off"]["psnr"]
