"""The harmonizer as insertion sees it: ``(image [H,W,3], region [H,W] bool) -> image``.

Wraps the RePaint sampler of :mod:`symdrive_core.diffusion.harmonize` with the restorer model,
so evaluation, fine-tuning and tests can pass any function of that shape.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

Harmonizer = Callable[[np.ndarray, np.ndarray], np.ndarray]


# RePaint with the shipped restorer: 10 steps, the first 20 % skipped (start at t = 0.8, noisy
# enough to re-light the vehicle). The paper's 50 steps measure worse with this small model,
# whose errors add up per step (`symdrive bench accuracy-time`, knob "harmonize steps").
DEFAULT_STEPS = 10
DEFAULT_START_FRACTION = 0.2


def restorer_harmonizer(restorer, *, steps: int | None = None, start_fraction: float = DEFAULT_START_FRACTION,
                        seed: int = 0, **options) -> Harmonizer:
    """Harmonize with ``restorer`` (the diffusion stack's model) in ``steps`` sampler steps,
    starting ``start_fraction`` of the way down the schedule from the noised insertion."""
    from ..diffusion.harmonize import harmonize

    steps = DEFAULT_STEPS if steps is None else int(steps)
    n_start = round(start_fraction * steps)

    def run(image: np.ndarray, region: np.ndarray) -> np.ndarray:
        return np.asarray(harmonize(restorer, image, region, steps=steps, n_start=n_start, seed=seed, **options),
                          dtype=np.float32)

    return run
