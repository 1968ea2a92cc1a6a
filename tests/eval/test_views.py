import numpy as np

from symdrive_core.eval.views import evaluate_heldout, evaluate_lateral
from symdrive_core.scene import load_manifest


def test_the_true_scene_scores_perfectly_at_every_ground_truth_camera(synthetic_package):
    """The ground truth was rendered from these Gaussians at the shifted cameras, so any
    mistake in which camera is evaluated (sign or axis of the shift) would cost many dB."""
    root, truth = synthetic_package
    m = load_manifest(root)
    held = evaluate_heldout(m, truth)
    assert held["frames"] == 2 and held["psnr_heldout"] > 40 and held["ssim_heldout"] > 0.99
    rows = evaluate_lateral(m, truth)
    assert [r["offset_m"] for r in rows] == [-0.5, 0.5]
    assert all(r["method"] == "raw_3dgs" and r["frames"] == 3 and r["psnr"] > 40 for r in rows)


def test_a_perturbed_scene_scores_worse(synthetic_package):
    root, truth = synthetic_package
    m = load_manifest(root)
    moved = truth.subset(np.arange(len(truth)))
    moved.means = moved.means + np.array([0.3, 0.0, 0.0], np.float32)
    assert evaluate_heldout(m, moved)["psnr_heldout"] < evaluate_heldout(m, truth)["psnr_heldout"] - 5
