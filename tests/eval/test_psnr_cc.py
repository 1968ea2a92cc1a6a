"""The colour-corrected PSNR: checked against a least-squares fit written out here, and on the
cases a per-image fit makes hard (a constant view, a view already exact)."""

import numpy as np
import pytest

from symdrive_core.eval.views import evaluate_lateral
from symdrive_core.metrics import psnr, psnr_cc
from symdrive_core.scene import load_manifest


def _oracle(view: np.ndarray, truth: np.ndarray) -> float:
    """Each truth channel regressed on (r, g, b, 1) separately, clipped, scored from the MSE."""
    x, y = view.astype(np.float64).reshape(-1, 3), truth.astype(np.float64).reshape(-1, 3)
    basis = np.column_stack([x[:, 0], x[:, 1], x[:, 2], np.ones(len(x))])
    fitted = np.stack([basis @ np.linalg.lstsq(basis, y[:, c], rcond=None)[0] for c in range(3)], axis=1)
    err = np.mean((np.clip(fitted, 0.0, 1.0) - y) ** 2)
    return float(-10.0 * np.log10(err))


def _pair(seed: int, shape=(24, 32, 3)) -> tuple[np.ndarray, np.ndarray]:
    """A truth image and a view of it with a colour cast, structure errors and noise."""
    rng = np.random.default_rng(seed)
    truth = rng.uniform(0.0, 1.0, shape)
    cast = np.array([[0.8, 0.1, 0.0], [0.05, 0.9, 0.05], [0.0, 0.1, 0.7]])
    view = truth @ cast.T + 0.05 + rng.normal(0.0, 0.05, shape)
    view[: shape[0] // 3] = rng.uniform(0.0, 1.0, (shape[0] // 3, *shape[1:]))  # a region the view gets wrong
    return np.clip(view, 0.0, 1.0).astype(np.float32), truth.astype(np.float32)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_matches_a_float64_least_squares_oracle(seed):
    view, truth = _pair(seed)
    assert psnr_cc(view, truth) == pytest.approx(_oracle(view, truth), abs=1e-9)


def test_clipping_after_the_fit_counts():
    """A view whose fit overshoots [0, 1] (truth saturated where the view is not)."""
    rng = np.random.default_rng(3)
    view = rng.uniform(0.0, 1.0, (16, 16, 3))
    truth = np.clip(1.6 * view - 0.3 + rng.normal(0.0, 0.02, view.shape), 0.0, 1.0)
    assert psnr_cc(view, truth) == pytest.approx(_oracle(view, truth), abs=1e-9)


def test_invariant_to_an_affine_colour_change_of_the_view():
    view, truth = _pair(4)
    view = 0.25 + 0.5 * view.astype(np.float64)  # room to move without leaving [0, 1]
    mix = np.array([[0.7, 0.2, 0.05], [0.1, 0.6, 0.1], [0.05, 0.15, 0.75]])
    moved = view @ mix.T + np.array([0.02, -0.05, 0.03])
    assert 0.0 <= moved.min() and moved.max() <= 1.0
    assert psnr_cc(moved, truth) == pytest.approx(psnr_cc(view, truth), abs=1e-7)
    assert abs(psnr(moved, truth) - psnr(view, truth)) > 0.5  # the plain score does move


@pytest.mark.parametrize("seed", range(5))
def test_never_below_plain_psnr(seed):
    view, truth = _pair(seed)
    assert psnr_cc(view, truth) >= psnr(view, truth)
    assert psnr_cc(truth * 0.9 + 0.05, truth) >= psnr(truth * 0.9 + 0.05, truth)


def test_a_constant_view_scores_the_truths_mean_colour():
    """[r, g, b, 1] has rank 1 there: the normal equations are singular, the fit is not."""
    _, truth = _pair(5)
    flat = np.full_like(truth, 0.4)
    mean_colour = np.tile(truth.reshape(-1, 3).mean(0), (*truth.shape[:2], 1))
    score = psnr_cc(flat, truth)
    assert np.isfinite(score) and score == pytest.approx(psnr(mean_colour, truth), abs=1e-9)


def test_a_view_equal_to_its_truth_scores_inf_as_psnr_does():
    _, truth = _pair(6)
    assert psnr(truth, truth) == psnr_cc(truth, truth) == float("inf")
    flat = np.full((8, 8, 3), 0.3)
    assert psnr_cc(flat, flat) == float("inf")


def test_shapes_must_agree():
    with pytest.raises(ValueError, match="psnr_cc"):
        psnr_cc(np.zeros((4, 4, 3)), np.zeros((4, 5, 3)))


def test_lateral_rows_carry_it(synthetic_package):
    root, truth = synthetic_package
    moved = truth.subset(np.arange(len(truth)))
    moved.means = moved.means + np.array([0.1, 0.0, 0.0], np.float32)
    rows = evaluate_lateral(load_manifest(root), moved)
    assert rows and all(np.isfinite(r["psnr_cc"]) and r["psnr_cc"] >= r["psnr"] for r in rows)
