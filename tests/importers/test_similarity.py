"""Similarity transforms of splats: SH colours rotate with the world, covariances scale and turn."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from symdrive_core.importers.similarity import decompose, make_similarity, rotate_sh, transform_gaussians
from symdrive_core.rotations import quat_normalize, quat_to_matrix
from symdrive_core.splat.sh import eval_sh_torch

from ..conftest import random_gaussians


def _rot(seed):
    return quat_to_matrix(quat_normalize(np.random.default_rng(seed).normal(size=4)))


@pytest.mark.parametrize("degree", [1, 2, 3])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rotated_sh_seen_from_rotated_directions_is_the_original(degree, seed):
    rng = np.random.default_rng(seed)
    R = _rot(seed + 10)
    sh = rng.normal(size=(50, (degree + 1) ** 2, 3))
    d = rng.normal(size=(50, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    before = eval_sh_torch(degree, torch.tensor(sh), torch.tensor(d)).numpy()
    after = eval_sh_torch(degree, torch.tensor(rotate_sh(sh, R)), torch.tensor(d @ R.T)).numpy()
    np.testing.assert_allclose(after, before, atol=1e-9)


def test_identity_and_composition():
    sh = np.random.default_rng(3).normal(size=(5, 16, 3))
    np.testing.assert_allclose(rotate_sh(sh, np.eye(3)), sh, atol=1e-12)
    A, B = _rot(4), _rot(5)
    np.testing.assert_allclose(rotate_sh(rotate_sh(sh, A), B), rotate_sh(sh, B @ A), atol=1e-9)


def test_transform_gaussians_moves_means_and_scales_covariances():
    g = random_gaussians(40, degree=1, seed=2)
    R, s, t = _rot(6), 0.37, np.array([370.0, -20.0, 5.0])
    T = make_similarity(s, R, t)
    h = transform_gaussians(g, T)
    np.testing.assert_allclose(h.means, g.means @ (s * R).T + t, atol=1e-3)

    def cov(x):
        Rq = quat_to_matrix(x.unit_quats.astype(np.float64))
        S = np.exp(2 * x.log_scales.astype(np.float64))
        return np.einsum("nij,nj,nkj->nik", Rq, S, Rq)

    np.testing.assert_allclose(cov(h), s * s * R @ cov(g) @ R.T, rtol=1e-4, atol=1e-9)
    np.testing.assert_array_equal(h.opacity_logits, g.opacity_logits)
    s2, R2, t2 = decompose(T)
    assert abs(s2 - s) < 1e-12 and np.allclose(R2, R) and np.allclose(t2, t)
