"""The harmonizer as insertion sees it: ``(image [H,W,3], region [H,W] bool) -> image``.

Wraps the RePaint sampler of :mod:`symdrive_core.diffusion.harmonize` with the restorer model,
so evaluation, fine-tuning and tests can pass any function of that shape.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

Harmonizer = Callable[[np.ndarray, np.ndarray], np.ndarray]


# RePaint with the shipped restorer: 10 steps, the first 20 % skipped (start at t = 0.8, noisy
# enough to re-light the vehicle), the mean of 4 samples. The paper's 50 steps and single sample
# measure worse with this small model, whose errors add up per step and differ per sample
# (`symdrive bench accuracy-time`, knobs "harmonize steps" and "harmonize samples").
DEFAULT_STEPS = 10
DEFAULT_START_FRACTION = 0.2
DEFAULT_SAMPLES = 4


def restorer_harmonizer(restorer, *, steps: int | None = None, start_fraction: float = DEFAULT_START_FRACTION,
                        samples: int = DEFAULT_SAMPLES, seed: int = 0, **options) -> Harmonizer:
    """Harmonize with ``restorer`` (the diffusion stack's model) in ``steps`` sampler steps,
    starting ``start_fraction`` of the way down the schedule from the noised insertion; the
    mean of ``samples`` harmonizations."""
    from ..diffusion.harmonize import harmonize

    steps = DEFAULT_STEPS if steps is None else int(steps)
    n_start = round(start_fraction * steps)

    def run(image: np.ndarray, region: np.ndarray) -> np.ndarray:
        return np.asarray(harmonize(restorer, image, region, steps=steps, n_start=n_start, samples=samples,
                                    seed=seed, **options), dtype=np.float32)

    return run
