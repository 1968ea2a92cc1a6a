"""The harmonizer as insertion sees it: ``(image [H,W,3], region [H,W] bool) -> image``.

Wraps the RePaint sampler of :mod:`symdrive_core.diffusion.harmonize` with the restorer model,
so evaluation, fine-tuning and tests can pass any function of that shape.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .config import HarmonizeConfig

Harmonizer = Callable[[np.ndarray, np.ndarray], np.ndarray]


def restorer_harmonizer(restorer, config: HarmonizeConfig = HarmonizeConfig(), **options) -> Harmonizer:
    """Harmonize with ``restorer`` (the diffusion stack's model) in ``config.steps`` sampler steps,
    starting ``config.start_fraction`` of the way down the schedule from the noised insertion; the
    mean of ``config.samples`` harmonizations. ``options`` go to the sampler (memory, crop margin)."""
    from ..diffusion.harmonize import harmonize

    steps = int(config.steps)
    n_start = round(config.start_fraction * steps)

    def run(image: np.ndarray, region: np.ndarray) -> np.ndarray:
        return np.asarray(harmonize(restorer, image, region, steps=steps, n_start=n_start, samples=config.samples,
                                    seed=config.seed, **options), dtype=np.float32)

    return run
