import numpy as np

from symdrive_core.eval.insertion import evaluate_insertion
from symdrive_core.insertion.insert import InsertionConfig
from symdrive_core.insertion.placements import held_out_placements, training_views
from symdrive_core.optim.finetune import FinetuneConfig
from symdrive_core.scene import load_manifest
from tests.insertion import package


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


def test_cast_shadow_matches_the_boxs_true_shadow(tmp_path):
    from symdrive_core.insertion.assets import load_vehicle_asset
    from symdrive_core.insertion.insert import insert_frame
    from symdrive_core.io.images import read_image, read_mask
    from symdrive_core.metrics import psnr
    from symdrive_core.splat.tensors import GaussianTensors

    path, bg = package.write_package(tmp_path / "pkg", sun=package.SUN)
    manifest = load_manifest(path)
    p = held_out_placements(manifest)[0]
    car = load_vehicle_asset(manifest.resolve(p.asset)).gaussians
    frame = insert_frame(manifest, GaussianTensors.from_gaussians(bg), car, p.pose, p.wlh, p.camera)
    truth = read_mask(manifest.resolve(p.shadow_mask)) > 0.5
    cast = (frame.shadow.occlusion > 0.5) & (frame.vehicle_alpha < 0.5)  # the truth marks uncovered ground only
    assert truth.sum() > 40
    assert (cast & truth).sum() / (cast | truth).sum() > 0.8
    assert frame.region[truth].all()  # harmonization may reach every truly shadowed pixel
    gt = read_image(manifest.resolve(p.with_image), channels=3)
    # the box's shade at the scene's ratio: far closer to the truth than the unshaded render
    assert psnr(frame.image, gt, truth) > psnr(frame.plain, gt, truth) + 12.0
    rows = {r["method"]: r for r in evaluate_insertion(manifest, bg, harmonizer=package.relight_region,
                                                       config=InsertionConfig(train_views=3, finetune=FinetuneConfig(
                                                           steps=40, lr_sh0=2e-2)), progress=False)}
    assert list(rows) == ["naive", "color_transfer", "cast_shadow", "harmonized", "finetuned", "finetuned_shadow"]
    # over car and shadow together the car's light dominates; the shadow still adds
    assert rows["cast_shadow"]["masked_psnr"] > rows["naive"]["masked_psnr"] + 0.5
    assert rows["finetuned_shadow"]["masked_psnr"] > rows["finetuned"]["masked_psnr"] + 0.5


def test_an_insertion_casts_a_shadow_exactly_where_the_plan_says(tmp_path):
    """One rule (``Effects.casting_sun``) for the planner and every renderer of an insertion: a sun
    at or below the horizon, or shadows off, give neither a cast shadow nor a shadow region."""
    from dataclasses import replace

    from symdrive_core.insertion.assets import load_vehicle_asset
    from symdrive_core.insertion.insert import insert_frame
    from symdrive_core.pipeline.plan import make_plan
    from symdrive_core.shadows.region import harmonization_region
    from symdrive_core.splat.tensors import GaussianTensors

    path, bg = package.write_package(tmp_path / "pkg", sun=package.SUN)
    manifest = load_manifest(path)
    p = held_out_placements(manifest)[0]
    car = load_vehicle_asset(manifest.resolve(p.asset)).gaussians
    background = GaussianTensors.from_gaussians(bg)
    low = replace(manifest.effects, sun_direction=np.array([1.0, 0.0, 0.0005]))
    for effects, casts in ((manifest.effects, True), (replace(manifest.effects, shadows=False), False), (low, False)):
        scene = replace(manifest, effects=effects)
        frame = insert_frame(scene, background, car, p.pose, p.wlh, p.camera)
        assert (frame.shadow is not None) == casts == (scene.effects.casting_sun()[0] is not None)
        if not casts:  # harmonization may change the car alone
            assert np.array_equal(frame.region, harmonization_region(frame.vehicle_alpha, None))
        reason = make_plan(scene).stage("cast_shadow").reason
        assert reason == scene.effects.casting_sun()[1] or (casts and "no vehicle that casts a shadow" in reason)
