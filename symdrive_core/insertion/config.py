"""Defaults of harmonization and of the insertion's fine-tune, as config dataclasses that import
no torch (the pipeline's options and the command line compose them; ``harmonizer.py`` and
``insert.py`` use them).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..optim.config import FinetuneConfig

MESH_SAMPLES = 12000  # Gaussians sampled from a mesh-only vehicle asset (mesh_to_splats)


@dataclass(frozen=True)
class HarmonizeConfig:
    """RePaint with the shipped restorer: 10 steps, the first 20 % skipped (start at t = 0.8,
    noisy enough to re-light the vehicle), the mean of 4 samples. The paper's 50 steps and single
    sample measure worse with this small model, whose errors add up per step and differ per sample
    (`symdrive bench accuracy-time`, knobs "harmonize steps" and "harmonize samples")."""

    steps: int = 10
    start_fraction: float = 0.2  # start this fraction of the way down, from the noised render
    samples: int = 4
    seed: int = 0


@dataclass(frozen=True)
class InpaintConfig:
    """RePaint over what an edit of a recorded vehicle exposes (:mod:`.exposed`), with the
    harmonizer's sampler; the region is grown by ``dilate_px`` to cover the vehicle's soft rim."""

    harmonize: HarmonizeConfig = HarmonizeConfig()
    dilate_px: int = 2


@dataclass
class InsertionConfig:
    train_views: int = 6
    crop_margin: int = 6  # pixels around the harmonized region kept for the fine-tune
    loss_ring_px: int = 2  # the fine-tune looks at the vehicle plus this ring (keeps opacity honest)
    shadow_dilate_px: int = 3
    finetune: FinetuneConfig = field(default_factory=FinetuneConfig)
    assets_out: Path | None = None  # write each fine-tuned asset here as a splat PLY
