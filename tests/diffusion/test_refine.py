import numpy as np

from symdrive_core.diffusion.refine import RefineConfig, refine_gaussians
from symdrive_core.diffusion.restore import RestoredView, score_gaussians
from symdrive_core.gaussians import Gaussians
from symdrive_core.scene import load_manifest
from symdrive_core.world.package import lateral_views
from tests.optim.conftest import render_truth, synthetic_package  # noqa: F401  (fixture)


def test_refining_on_good_lateral_views_improves_the_lateral_score(synthetic_package):  # noqa: F811
    root, truth = synthetic_package
    manifest = load_manifest(root)
    rng = np.random.default_rng(0)
    damaged = Gaussians(
        truth.means.copy(),
        truth.quats.copy(),
        truth.log_scales.copy(),
        truth.opacity_logits.copy(),
        truth.sh + rng.normal(scale=0.3, size=truth.sh.shape).astype(np.float32),
    )
    views = [
        RestoredView(
            v.frame,
            v.offset_m,
            v.K,
            v.camera_to_world,
            v.world_to_camera,
            v.width,
            v.height,
            render_truth(truth, v.camera_to_world, v.K)[0],
        )
        for v in lateral_views(manifest)
    ]
    before = np.mean([r["psnr"] for r in score_gaussians(manifest, damaged, "raw_3dgs")])
    refined, stats = refine_gaussians(
        manifest, damaged, views, RefineConfig(iters=40, depth_weight=0.0), progress=False
    )
    after = np.mean([r["psnr"] for r in score_gaussians(manifest, refined, "refined")])
    assert after > before + 1.0
    assert stats["restored_views"] == len(views) and stats["loss_last"] < stats["loss_first"]

    # the control (recorded views only, same draws of them) gains less where only lateral views look
    control, control_stats = refine_gaussians(
        manifest, damaged, [], RefineConfig(iters=40, depth_weight=0.0), progress=False
    )
    assert control_stats["restored_views"] == 0
    control_psnr = np.mean([r["psnr"] for r in score_gaussians(manifest, control, "control")])
    assert control_psnr < after
