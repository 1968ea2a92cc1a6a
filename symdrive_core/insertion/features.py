"""Frechet distance between real and inserted vehicle crops, with a feature extractor the
user supplies (never downloaded): ``path/to/file.py:function``, ``package.module:function`` or
a saved network the user has on disk (TorchScript ``.pt`` / ``.pth``, or ``torch.export`` ``.pt2``),
e.g. an Inception network for FID.

An extractor maps a float32 batch [N, 3, S, S] in [0, 1] to features [N, D].
"""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from ..errors import InputError
from ..metrics import bbox_crop, frechet_distance

Extractor = Callable[[torch.Tensor], torch.Tensor]


def load_extractor(spec: str) -> Extractor:
    """Resolve a ``--features-module`` argument to a callable."""
    if Path(spec).suffix == ".pt2":
        if not Path(spec).exists():
            raise InputError(spec, "feature extractor file not found")
        return torch.export.load(spec).module()
    if Path(spec).suffix in (".pt", ".pth"):
        if not Path(spec).exists():
            raise InputError(spec, "feature extractor file not found")
        return torch.jit.load(spec, map_location="cpu").eval()
    target, sep, name = spec.rpartition(":")
    if not sep or not target or not name:
        raise InputError(spec, "expected FILE.py:FUNCTION, MODULE:FUNCTION or a TorchScript .pt file")
    if target.endswith(".py"):
        path = Path(target)
        if not path.exists():
            raise InputError(path, "feature extractor module not found")
        mod_spec = importlib.util.spec_from_file_location(f"symdrive_features_{path.stem}", path)
        module = importlib.util.module_from_spec(mod_spec)
        mod_spec.loader.exec_module(module)
    else:
        module = importlib.import_module(target)
    fn = getattr(module, name, None)
    if not callable(fn):
        raise InputError(spec, f"{name!r} is not a callable in {target}")
    return fn


def vehicle_crop(image: np.ndarray, mask: np.ndarray, size: int = 64, margin: int = 4) -> np.ndarray:
    """Square-resized crop [size, size, 3] around a mask's bounding box."""
    box = bbox_crop(mask, margin)
    if box is None:
        raise ValueError("vehicle_crop: empty mask")
    crop = torch.as_tensor(np.ascontiguousarray(image[box][..., :3]), dtype=torch.float32).permute(2, 0, 1)[None]
    return F.interpolate(crop, size=(size, size), mode="bilinear", align_corners=False)[0].permute(1, 2, 0).numpy()


def features(extractor: Extractor, crops: list[np.ndarray]) -> np.ndarray:
    batch = torch.as_tensor(np.stack(crops), dtype=torch.float32).permute(0, 3, 1, 2)
    with torch.no_grad():
        out = extractor(batch)
    return np.asarray(out.detach().reshape(len(crops), -1).cpu().numpy() if isinstance(out, torch.Tensor) else out,
                      dtype=np.float64).reshape(len(crops), -1)


def crop_frechet(extractor: Extractor, real: list[np.ndarray], inserted: list[np.ndarray]) -> float:
    """Frechet distance between the extractor's features of two crop sets (N >= 2 each)."""
    return frechet_distance(features(extractor, real), features(extractor, inserted))
