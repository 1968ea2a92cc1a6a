"""3DGS refinement on restored lateral views (the paper's last step of novel-view synthesis).

The reconstruction is fine-tuned on its recorded views with ``L1 + lambda (1 - SSIM) +
w * depth`` and on restored views with ``L1 + lambda (1 - SSIM)`` (no depth: a restored image
carries none), one of each per iteration. With no restored views it trains on the recorded
ones alone: the control that tells what the restored views add. No densification: refinement
corrects colours and positions of the Gaussians the reconstruction already has, and the
position learning rate is the reconstruction's final (smallest) one so the geometry fitted to
the recorded views does not drift toward hallucinated detail.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from ..gaussians import Gaussians
from ..scene import Manifest
from .config import RefineConfig
from .restore import RestoredView


def refine_gaussians(
    manifest: Manifest,
    gaussians: Gaussians,
    restored: list[RestoredView],
    cfg: RefineConfig | None = None,
    *,
    progress: bool = True,
) -> tuple[Gaussians, dict]:
    """Fine-tune ``gaussians`` on the package's training views plus ``restored`` (may be empty:
    the control); (result, stats). The recorded views are drawn in the same order either way."""
    from tqdm import tqdm

    from ..optim.losses import photometric
    from ..optim.reconstruct import (
        ReconstructConfig,
        depth_loss,
        gaussians_from_params,
        load_views,
        make_optimizer,
        scene_extent,
    )
    from ..scene.ground_truth import split_frames
    from ..splat.render import params_from_gaussians, render_params

    cfg = cfg or RefineConfig()
    gt_views = load_views(manifest, split_frames(manifest)[0], depth=cfg.depth_weight > 0)
    extent, _ = scene_extent(gt_views)
    rc = ReconstructConfig()
    params = params_from_gaussians(gaussians, gaussians.sh_degree)
    opt = make_optimizer(params, rc, extent)
    for group in opt.param_groups:
        if group["name"] == "means":
            group["lr"] = rc.lr_means_final * extent
    novel = [
        (
            torch.tensor(v.K, dtype=torch.float32),
            torch.tensor(v.world_to_camera, dtype=torch.float32),
            torch.from_numpy(np.ascontiguousarray(v.image, dtype=np.float32)),
            v.width,
            v.height,
        )
        for v in restored
    ]
    rng_recorded, rng_restored = (np.random.default_rng([cfg.seed, k]) for k in (0, 1))
    first = last = None
    t0 = time.perf_counter()
    for _ in tqdm(range(cfg.iters), desc="refine", unit="it", disable=not progress):
        gv = gt_views[rng_recorded.integers(len(gt_views))]
        rgb, alpha, info = render_params(
            params,
            gv.K,
            gv.viewmat,
            gv.width,
            gv.height,
            gaussians.sh_degree,
            render_depth=cfg.depth_weight > 0,
        )
        loss = photometric(rgb, gv.image, cfg.ssim_lambda)
        if cfg.depth_weight > 0:
            dl = depth_loss(info, alpha, gv.depth)
            if dl is not None:
                loss = loss + cfg.depth_weight * dl
        if novel:
            K, viewmat, image, w, h = novel[rng_restored.integers(len(novel))]
            rgb, _, _ = render_params(params, K, viewmat, w, h, gaussians.sh_degree)
            loss = loss + cfg.novel_weight * photometric(rgb, image, cfg.ssim_lambda)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        last = float(loss.detach())
        first = last if first is None else first
    stats = {
        "iters": cfg.iters,
        "restored_views": len(restored),
        "recorded_views": len(gt_views),
        "loss_first": round(first, 5),
        "loss_last": round(last, 5),
        "seconds": round(time.perf_counter() - t0, 1),
    }
    return gaussians_from_params(params), stats
