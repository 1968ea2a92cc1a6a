"""Image quality metrics: PSNR, colour-corrected PSNR, SSIM (3DGS flavour), masked variants, mask
IoU, Frechet distance.

SSIM follows the 3DGS evaluation code: 11x11 Gaussian window, sigma 1.5, C1 = 0.01^2,
C2 = 0.03^2, zero padding ("same" convolution), mean over channels and pixels. Other
implementations (scikit-image's, for one) differ in the third decimal.
Images are [H, W, C] (numpy or torch) in [0, 1]; torch versions are differentiable.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

SSIM_WINDOW = 11
SSIM_SIGMA = 1.5
SSIM_C1 = 0.01 ** 2
SSIM_C2 = 0.03 ** 2


def _t(x, dtype=None) -> torch.Tensor:
    t = x if isinstance(x, torch.Tensor) else torch.as_tensor(np.asarray(x))
    return t.to(dtype) if dtype is not None else t


def _gaussian_window(dtype, device) -> torch.Tensor:
    """The SSIM window's 1D factor: the 11x11 window is its outer product with itself."""
    x = torch.arange(SSIM_WINDOW, dtype=torch.float64) - SSIM_WINDOW // 2
    g = torch.exp(-(x ** 2) / (2 * SSIM_SIGMA ** 2))
    return (g / g.sum()).to(dtype=dtype, device=device)


def ssim_map(a, b) -> torch.Tensor:
    """Per-pixel SSIM [H, W] (mean over channels) of two [H, W, C] images.

    The five local moments are blurred in one grouped convolution per axis: the Gaussian window
    is separable, so a row pass then a column pass (zero padding each) equals the 11x11 window
    with 22 taps instead of 121, which is most of the loss's cost in a reconstruction step."""
    a, b = _t(a), _t(b)
    dtype = a.dtype if a.is_floating_point() else torch.float32
    x = a.to(dtype).permute(2, 0, 1)[None]
    y = b.to(dtype).permute(2, 0, 1)[None]
    c = x.shape[1]
    g = _gaussian_window(dtype, x.device)
    pad = SSIM_WINDOW // 2
    z = torch.cat([x, y, x * x, y * y, x * y], dim=1)
    z = F.conv2d(z, g.view(1, 1, 1, -1).expand(5 * c, 1, 1, SSIM_WINDOW), padding=(0, pad), groups=5 * c)
    z = F.conv2d(z, g.view(1, 1, -1, 1).expand(5 * c, 1, SSIM_WINDOW, 1), padding=(pad, 0), groups=5 * c)
    mu_x, mu_y, bxx, byy, bxy = z.split(c, dim=1)
    sxx = bxx - mu_x ** 2
    syy = byy - mu_y ** 2
    sxy = bxy - mu_x * mu_y
    num = (2 * mu_x * mu_y + SSIM_C1) * (2 * sxy + SSIM_C2)
    den = (mu_x ** 2 + mu_y ** 2 + SSIM_C1) * (sxx + syy + SSIM_C2)
    return (num / den)[0].mean(0)


def _masked_mean(values: torch.Tensor, mask) -> torch.Tensor:
    if mask is None:
        return values.mean()
    m = _t(mask, values.dtype)
    if m.ndim == 3:
        m = m[..., 0]
    total = m.sum()
    if total <= 0:
        raise ValueError("mask is empty: the masked metric is undefined")
    return (values * m).sum() / total


def ssim(a, b, mask=None) -> float:
    """Mean SSIM; with ``mask`` [H, W], the mean of the SSIM map over the masked pixels."""
    with torch.no_grad():
        return float(_masked_mean(ssim_map(a, b), mask))


def mse(a, b, mask=None) -> float:
    a, b = _t(a, torch.float64), _t(b, torch.float64)
    return float(_masked_mean(((a - b) ** 2).mean(-1), mask))


def psnr(a, b, mask=None) -> float:
    """PSNR in dB for images in [0, 1]; ``mask`` restricts it to a region."""
    err = mse(a, b, mask)
    return float("inf") if err == 0 else float(10.0 * np.log10(1.0 / err))


def psnr_cc(view, truth) -> float:
    """PSNR after a per-image affine colour fit of ``view`` to ``truth`` (Mip-NeRF 360's
    colour-corrected PSNR, in its affine form).

    A [3, 4] matrix ``A`` is fitted by least squares over all pixels, ``truth ~ A @ [r, g, b, 1]``,
    the fitted view clipped to [0, 1] (as the reference evaluation codes do: truth lies there, so
    clipping only brings pixels closer) and scored with :func:`psnr`. It separates what a view
    shows from a global photometric difference (exposure, white balance, a second sensor) that no
    renderer or restorer can know. Mip-NeRF 360's own fit adds quadratic terms and drops saturated
    pixels; the affine one has 12 parameters per image, too few to paint in structure.

    ``numpy.linalg.lstsq`` in float64 keeps singular fits finite (a constant view: the fit is the
    truth's mean colour). The identity is one of the affine maps, so the score is never below
    plain PSNR; the larger of the two is returned so that the fit's round-off cannot put it there
    (a view equal to its truth scores inf, as :func:`psnr` does).
    """
    x = np.asarray(view, dtype=np.float64)
    y = np.asarray(truth, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 3 or x.shape[-1] != 3:
        raise ValueError(f"psnr_cc needs two [H, W, 3] images of one shape, got {x.shape} and {y.shape}")
    design = np.concatenate([x.reshape(-1, 3), np.ones((x.shape[0] * x.shape[1], 1))], axis=1)
    fit, *_ = np.linalg.lstsq(design, y.reshape(-1, 3), rcond=None)  # [4, 3] = A transposed
    corrected = np.clip(design @ fit, 0.0, 1.0).reshape(y.shape)
    return max(psnr(corrected, y), psnr(x, y))


def bbox_crop(mask: np.ndarray, margin: int = 0) -> tuple[slice, slice] | None:
    """Bounding box of a mask's non-zero pixels as slices (None if empty)."""
    ys, xs = np.nonzero(np.asarray(mask) > 0)
    if ys.size == 0:
        return None
    h, w = np.asarray(mask).shape[:2]
    return (slice(max(0, ys.min() - margin), min(h, ys.max() + 1 + margin)),
            slice(max(0, xs.min() - margin), min(w, xs.max() + 1 + margin)))


def mask_iou(pred: np.ndarray, truth: np.ndarray) -> float:
    """Intersection over union of two boolean masks of one shape. Two empty masks agree
    perfectly (1.0): a view with no lane paint is scored right when none is found."""
    pred, truth = np.asarray(pred, dtype=bool), np.asarray(truth, dtype=bool)
    if pred.shape != truth.shape:
        raise ValueError(f"mask_iou: shapes differ, {pred.shape} vs {truth.shape}")
    union = int(np.count_nonzero(pred | truth))
    return 1.0 if union == 0 else int(np.count_nonzero(pred & truth)) / union


def frechet_distance(feats_a: np.ndarray, feats_b: np.ndarray) -> float:
    """Frechet distance between Gaussians fitted to two feature sets [N, D].

    ||mu_a - mu_b||^2 + Tr(S_a + S_b - 2 (S_a S_b)^(1/2)); the square root is taken as
    S_a^(1/2) S_b S_a^(1/2) symmetrised, whose eigenvalues are real and non-negative, so it stays
    stable where S_a S_b is near singular (few samples).
    """
    a = np.asarray(feats_a, dtype=np.float64)
    b = np.asarray(feats_b, dtype=np.float64)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1] or min(len(a), len(b)) < 2:
        raise ValueError("frechet_distance needs two [N, D] feature arrays with N >= 2")
    mu_a, mu_b = a.mean(0), b.mean(0)
    s_a, s_b = np.cov(a, rowvar=False), np.cov(b, rowvar=False)
    s_a, s_b = np.atleast_2d(s_a), np.atleast_2d(s_b)
    ea, va = np.linalg.eigh(s_a)
    sqrt_a = (va * np.sqrt(np.clip(ea, 0, None))) @ va.T
    m = sqrt_a @ s_b @ sqrt_a
    em = np.linalg.eigvalsh(0.5 * (m + m.T))
    tr_sqrt = np.sqrt(np.clip(em, 0, None)).sum()
    return float(((mu_a - mu_b) ** 2).sum() + np.trace(s_a) + np.trace(s_b) - 2.0 * tr_sqrt)
