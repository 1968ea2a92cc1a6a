"""Gaussian splat rendering: projection, SH, tile rasterizer (forward + backward), composition.

Imports are lazy so that light modules (command registration) do not load torch or numba:
``from symdrive_core.splat import rasterize`` works as usual. ``symdrive_core.splat.rasterize`` is
the function; its module is reached as ``symdrive_core.splat.rasterize`` through ``import`` /
``from ... import`` statements (``sys.modules``), which is unaffected.
"""

from __future__ import annotations

import importlib
import sys
import types

_EXPORTS = {
    "rasterize": ".rasterize",
    "RasterizePixels": ".rasterize",
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


class _Package(types.ModuleType):
    def __getattr__(self, name):
        if name in _EXPORTS:
            value = getattr(importlib.import_module(_EXPORTS[name], __name__), name)
            types.ModuleType.__setattr__(self, name, value)
            return value
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

    def __setattr__(self, name, value):
        # Loading a submodule binds it on the package; the exported function of the same name wins.
        if name in _EXPORTS and isinstance(value, types.ModuleType):
            self.__dict__.pop(name, None)
            return
        types.ModuleType.__setattr__(self, name, value)


sys.modules[__name__].__class__ = _Package
