"""The demo package's lane-marking masks lie on the painted lines of its Cycles images, and the
segmenter finds those lines on the Cycles images themselves (the lane-IoU ceiling)."""

import shutil

import numpy as np
import pytest

from symdrive_core.errors import InputError
from symdrive_core.eval.lane_paint import lane_truth
from symdrive_core.io.images import read_image
from symdrive_core.scene import load_manifest
from symdrive_core.scene.ground_truth import lane_masks, lateral_views
from symdrive_core.world.demo import DEMO_PACKAGE

MANIFEST = load_manifest(DEMO_PACKAGE)
RECORDED = [0, 7, 14, 21, 28]
LATERAL = [v for v in lateral_views(MANIFEST) if v.frame in (2, 12, 22) and abs(v.offset_m) in (1.0, 3.0)]


def _recorded(i: int):
    cf = MANIFEST.cameras[0].frames[i]
    return (lane_truth(MANIFEST, lane_masks(MANIFEST)[("front", 0.0, i)], cf.K, cf.camera_to_world),
            read_image(MANIFEST.resolve(cf.image), channels=3))


def _lateral(v):
    return lane_truth(MANIFEST, v.lanes, v.K, v.camera_to_world), read_image(MANIFEST.resolve(v.image), channels=3)


def test_every_ground_truth_view_has_a_lane_mask():
    masks = lane_masks(MANIFEST)
    assert all(("front", 0.0, i) in masks for i in range(len(MANIFEST.frames)))
    assert all(("front", v.offset_m, v.frame) in masks for v in lateral_views(MANIFEST))
    assert len(LATERAL) == 12 and all(v.lanes is not None for v in LATERAL)


@pytest.mark.parametrize("view", ["recorded", "lateral"])
def test_masks_lie_on_the_painted_lines(view):
    """Inside the road, mask pixels are far brighter than the asphalt around them."""
    pairs = [_recorded(i) for i in RECORDED] if view == "recorded" else [_lateral(v) for v in LATERAL]
    for lanes, img in pairs:
        value = img.max(axis=2)
        assert lanes.mask.sum() > 50
        assert value[lanes.mask].mean() > value[lanes.region & ~lanes.mask].mean() + 0.3


@pytest.mark.parametrize("view", ["recorded", "lateral"])
def test_the_segmenter_finds_the_lines_on_the_cycles_images(view):
    """The ceiling: measured 89.4 (recorded frames) and 86.8 to 89.0 (lateral views) IoU points."""
    pairs = [_recorded(i) for i in RECORDED] if view == "recorded" else [_lateral(v) for v in LATERAL]
    assert np.mean([lanes.iou(img) for lanes, img in pairs]) > 0.8


def test_a_missing_lane_mask_stops_restore_evaluate_with_exit_2(tmp_path, capsys):
    from symdrive_core.cli import main

    pkg = tmp_path / "pkg"
    shutil.copytree(DEMO_PACKAGE, pkg, ignore=shutil.ignore_patterns("output"))
    gone = lane_masks(MANIFEST)[("front", 0.5, 12)]
    (pkg / gone).unlink()
    copy = load_manifest(pkg)
    v = next(v for v in lateral_views(copy) if v.lanes == gone)
    with pytest.raises(InputError, match="file not found"):
        lane_truth(copy, v.lanes, v.K, v.camera_to_world)
    out = tmp_path / "eval"
    assert main(["restore", str(pkg), "--frames", "12", "--evaluate", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert gone in err and err.strip().count("\n") == 0
    assert not (out / "metrics.json").exists()


def test_lateral_rows_carry_lane_iou_and_its_ceiling():
    """``evaluate_lateral`` rows (raw 3DGS at 3 m, frame 12): lane IoU of the render and, beside
    it, the segmenter's IoU on the Cycles images of the same views."""
    from symdrive_core.eval.views import evaluate_lateral
    from symdrive_core.io.ply import read_splats
    from symdrive_core.scene.ground_truth import with_lateral_offsets

    scoped = with_lateral_offsets(MANIFEST, [-3.0, 3.0])
    rows = evaluate_lateral(scoped, read_splats(MANIFEST.resolve(MANIFEST.background_splats)), "raw_3dgs", [12])
    assert [(r["offset_m"], r["frames"]) for r in rows] == [(-3.0, 1), (3.0, 1)]
    for r in rows:
        v = next(v for v in lateral_views(scoped) if v.offset_m == r["offset_m"] and v.frame == 12)
        lanes, cycles = _lateral(v)
        assert r["lane_iou_ceiling"] == pytest.approx(100 * lanes.iou(cycles), abs=0.005)
        assert 0.0 <= r["lane_iou"] <= 100.0


def test_rows_have_no_lane_iou_without_lane_masks():
    from symdrive_core.eval.views import lateral_rows

    scores = [{"psnr": 25.0, "ssim": 0.8, "psnr_cc": 26.0}, {"psnr": 27.0, "ssim": 0.9, "psnr_cc": 29.0}]
    rows = lateral_rows({(1.0, "raw_3dgs"): scores}, {}, {})
    assert rows == [{"offset_m": 1.0, "method": "raw_3dgs", "psnr": 26.0, "ssim": 0.85, "psnr_cc": 27.5, "frames": 2}]
