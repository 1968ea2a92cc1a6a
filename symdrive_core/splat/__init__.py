"""Gaussian splat rendering: projection, SH, tile rasterizer (forward + backward), composition.

The public names are re-exported here; each is imported on first use (a module ``__getattr__``),
so light modules (command registration) do not load torch or numba. The rasterizer function
``rasterize`` lives in the module ``rasterizer`` (gsplat's ``rasterization`` in ``rendering.py``):
module and function never share a name, so neither hides the other.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "rasterize": ".rasterizer",
    "RasterizePixels": ".rasterizer",
    "eval_sh": ".sh",
    "sh_to_color": ".sh",
    "GaussianTensors": ".tensors",
    "Layer": ".render",
    "render_layers": ".render",
    "SplatRenderer": ".render",
    "render_oracle": ".oracle",
    "project_gaussians": ".projection",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name], __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
