import numpy as np

from symdrive_core.insertion.evaluate import InsertionConfig, evaluate_insertion
from symdrive_core.insertion.placements import held_out_placements, training_views
from symdrive_core.optim.finetune import FinetuneConfig
from symdrive_core.scene import load_manifest

from . import package


def test_insertion_rows_on_a_package_with_known_truth(tmp_path):
    path, bg = package.write_package(tmp_path / "pkg")
    manifest = load_manifest(path)
    placement = held_out_placements(manifest)[0]
    views = training_views(manifest, placement, manifest.ground_truth["train_frames"], 4)
    assert views and package.HELD not in views
    details = {}
    cfg = InsertionConfig(train_views=4, finetune=FinetuneConfig(steps=80, lr_sh0=2e-2),
                          assets_out=tmp_path / "assets")
    rows = evaluate_insertion(manifest, bg, harmonizer=package.relight_region, config=cfg, details=details,
                              progress=False)
    by = {r["method"]: r for r in rows}
    assert list(by) == ["naive", "color_transfer", "harmonized", "finetuned"]
    for r in rows:
        assert set(r) >= {"masked_psnr", "masked_ssim", "psnr"} and np.isfinite(r["masked_psnr"])
    # The fine-tuned asset learned the light from other views and beats the studio asset.
    assert by["finetuned"]["masked_psnr"] > by["naive"]["masked_psnr"] + 6.0
    assert by["finetuned"]["psnr"] > by["naive"]["psnr"]
    assert details["timings"]["finetune_views"] == [len(views)]
    assert len(list((tmp_path / "assets").glob("*.ply"))) == 1


def test_without_a_harmonizer_only_baselines_are_measured(tmp_path):
    path, bg = package.write_package(tmp_path / "pkg")
    rows = evaluate_insertion(load_manifest(path), bg, progress=False)
    assert [r["method"] for r in rows] == ["naive", "color_transfer"]
