"""SSIM against a float64 oracle with the 11x11 window written out (the separable blur must equal
it, zero padding included), its gradient by finite differences, and its hard cases."""

import numpy as np
import torch

from symdrive_core.metrics import SSIM_C1, SSIM_C2, SSIM_SIGMA, SSIM_WINDOW, ssim, ssim_map


def oracle_ssim_map(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """SSIM with the 2D window applied offset by offset over zero-padded float64 images."""
    r = SSIM_WINDOW // 2
    u = np.arange(-r, r + 1, dtype=np.float64)
    w2 = np.exp(-(u[:, None] ** 2 + u[None, :] ** 2) / (2 * SSIM_SIGMA ** 2))
    w2 /= w2.sum()
    h, w, _ = a.shape

    def blur(z):
        zp = np.pad(z, ((r, r), (r, r), (0, 0)))
        return sum(w2[i, j] * zp[i:i + h, j:j + w] for i in range(SSIM_WINDOW) for j in range(SSIM_WINDOW))

    mx, my = blur(a), blur(b)
    sxx, syy, sxy = blur(a * a) - mx ** 2, blur(b * b) - my ** 2, blur(a * b) - mx * my
    s = ((2 * mx * my + SSIM_C1) * (2 * sxy + SSIM_C2)) / ((mx ** 2 + my ** 2 + SSIM_C1) * (sxx + syy + SSIM_C2))
    return s.mean(-1)


def test_ssim_map_matches_the_2d_window_oracle_to_float64_precision():
    rng = np.random.default_rng(0)
    a, b = rng.random((23, 31, 3)), rng.random((23, 31, 3))
    b = 0.6 * a + 0.4 * b  # correlated, as a render and its photo are
    got = ssim_map(torch.from_numpy(a), torch.from_numpy(b)).numpy()
    assert np.abs(got - oracle_ssim_map(a, b)).max() < 1e-12


def test_ssim_in_float32_stays_close_to_the_oracle():
    rng = np.random.default_rng(1)
    a = rng.random((40, 64, 3)).astype(np.float32)
    b = np.clip(a + 0.05 * rng.standard_normal(a.shape), 0, 1).astype(np.float32)
    got = ssim_map(torch.from_numpy(a), torch.from_numpy(b)).numpy()
    assert np.abs(got - oracle_ssim_map(a.astype(np.float64), b.astype(np.float64))).max() < 1e-4


def test_ssim_gradient_matches_finite_differences():
    rng = np.random.default_rng(2)
    a = torch.from_numpy(rng.random((9, 13, 3))).requires_grad_(True)
    b = torch.from_numpy(rng.random((9, 13, 3)))
    assert torch.autograd.gradcheck(lambda x: ssim_map(x, b).mean(), (a,), eps=1e-6, atol=1e-7)


def test_hard_cases_identical_flat_and_image_smaller_than_the_window():
    rng = np.random.default_rng(3)
    a = rng.random((16, 20, 3))
    assert abs(ssim(a, a) - 1.0) < 1e-12
    flat = np.full((8, 8, 3), 0.5)  # zero variance everywhere: the constants keep it finite
    assert abs(ssim(flat, flat) - 1.0) < 1e-12
    tiny_a, tiny_b = rng.random((3, 4, 3)), rng.random((3, 4, 3))  # smaller than the 11-pixel window
    got = ssim_map(torch.from_numpy(tiny_a), torch.from_numpy(tiny_b)).numpy()
    assert np.isfinite(got).all() and np.allclose(got, oracle_ssim_map(tiny_a, tiny_b), atol=1e-12)
