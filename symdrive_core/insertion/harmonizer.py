"""The harmonizer as insertion sees it: ``(image [H,W,3], region [H,W] bool) -> image``.

Wraps the RePaint sampler of :mod:`symdrive_core.diffusion.harmonize` with the restorer model,
so evaluation, fine-tuning and tests can pass any function of that shape.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

Harmonizer = Callable[[np.ndarray, np.ndarray], np.ndarray]


def restorer_harmonizer(restorer, *, steps: int | None = None, seed: int = 0, **options) -> Harmonizer:
    """Harmonize with ``restorer`` (the diffusion stack's model) in ``steps`` sampler steps."""
    from ..diffusion.harmonize import harmonize

    def run(image: np.ndarray, region: np.ndarray) -> np.ndarray:
        kw = dict(options, seed=seed)
        if steps is not None:
            kw["steps"] = steps
        return np.asarray(harmonize(restorer, image, region, **kw), dtype=np.float32)

    return run
