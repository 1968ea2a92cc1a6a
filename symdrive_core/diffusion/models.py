"""Restorer backends behind one interface, and the loader that picks one.

A restorer predicts the flow velocity of the centre view from its two side views:
``velocity(z_t, t, cond_left, cond_right)`` on latents [B, C, h, w], with ``latent`` mapping
images to that space and ``time_shift(latent_shape)`` the schedule's shift ``mu``.
Two implementations:

* ``BuiltinRestorer`` (default): the small pixel-space UNet whose trained weights ship with the
  package, so restoration and harmonization run offline on a CPU.
* ``FluxRestorer`` (:mod:`.flux`): Flux.1-dev + LoRA from local files, when the user has them.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import torch

from ..errors import InputError
from ..io.atomic import atomic_path
from .defaults import DEFAULT_WEIGHTS, GUIDED_WEIGHTS
from .latent import PixelSpace
from .unet import UNet, UNetConfig


class BuiltinRestorer:
    """The shipped UNet in pixel space (no time shift). ``guided``: the restorer the
    geometry-guided methods sample with instead of this one (None: this one); ``strength``: the
    share of its correction a sampler keeps unless told otherwise, ``keep_warp``: whether its
    views keep the warp where frames saw the ground unless told otherwise (:mod:`.strength`)."""

    def __init__(self, net: UNet, guided: BuiltinRestorer | None = None, strength: float = 1.0,
                 keep_warp: bool = True):
        self.net = net
        self.guided = guided
        self.strength = strength
        self.keep_warp = keep_warp
        self.latent = PixelSpace()

    def time_shift(self, latent_shape) -> float:
        return 0.0

    @property
    def guide_channels(self) -> int:
        """Channels of the geometry-guided condition it takes (0: none)."""
        return self.net.config.guide_channels

    def encode_guide(self, guide: torch.Tensor) -> torch.Tensor:
        """Warp and mask [B, 4, H, W] in [0, 1] -> the network's [-1, 1] input."""
        return guide * 2.0 - 1.0

    def velocity(self, z_t, t, cond_left, cond_right, guide=None) -> torch.Tensor:
        """On the network's device (see :meth:`to`); the result on ``z_t``'s, where the sampler
        keeps its state."""
        device = self.net.inp.weight.device
        if z_t.device == device:
            return self.net(z_t, t, cond_left, cond_right, guide)
        inputs = [None if x is None else x.to(device) for x in (z_t, t, cond_left, cond_right, guide)]
        return self.net(*inputs).to(z_t.device)

    def to(self, device) -> BuiltinRestorer:
        """The network (and its guided sibling's) on ``device`` (``cpu``, ``cuda``...)."""
        self.net.to(device)
        if self.guided is not None:
            self.guided.to(device)
        return self

    def parameters(self):
        return self.net.parameters()

    def train(self, mode: bool = True) -> BuiltinRestorer:
        self.net.train(mode)
        return self


def save_builtin(path: str | os.PathLike, net: UNet, meta: dict | None = None, *, half: bool = False) -> Path:
    """Weights + config (in the safetensors metadata), written atomically."""
    from safetensors.torch import save_file

    dtype = torch.float16 if half else torch.float32
    tensors = {k: v.detach().to(dtype).contiguous() for k, v in net.state_dict().items()}
    metadata = {"config": json.dumps(net.config.to_json()), "meta": json.dumps(meta or {})}
    path = Path(path)
    with atomic_path(path) as tmp:
        save_file(tensors, str(tmp), metadata=metadata)
    return path


def load_builtin(path: str | os.PathLike = DEFAULT_WEIGHTS) -> BuiltinRestorer:
    from ..io.tensor_file import read_tensor_file

    path = Path(path)
    if not path.exists():
        raise InputError(path, "restorer weights not found (train them with `symdrive train-restorer`)")
    tensors, meta = read_tensor_file(path, "restorer weights")
    if "config" not in meta:
        raise InputError(path, "not a restorer checkpoint: no config in its metadata")
    try:
        net = UNet(UNetConfig.from_json(json.loads(meta["config"])))
    except (TypeError, ValueError, KeyError) as exc:  # a training checkpoint's config, say
        raise InputError(path, f"not restorer weights: its config is not a network's ({exc}); a training "
                               "checkpoint's weights are written beside it by `symdrive train-restorer`") from None
    if bad := [k for k, v in tensors.items() if v.is_floating_point() and not bool(torch.isfinite(v).all())]:
        raise InputError(path, f"{len(bad)} of {len(tensors)} weight tensors hold NaN or infinity ({bad[0]}, ...): "
                               "the training diverged; train again")
    try:
        net.load_state_dict({k: v.float() for k, v in tensors.items()})
    except RuntimeError as exc:
        raise InputError(path, f"weights do not match their config: {str(exc).splitlines()[0]}") from None
    recorded = _recorded(meta.get("meta"))
    return BuiltinRestorer(net.eval(), strength=_strength(path, recorded), keep_warp=_keep_warp(path, recorded))


def _recorded(meta: str | None) -> dict:
    try:
        value = json.loads(meta or "{}")
    except json.JSONDecodeError:
        return {}
    return value if isinstance(value, dict) else {}


def _strength(path: Path, meta: dict) -> float:
    """The strength the weights record (``meta.strength``, fitted by an adaptation), else 1."""
    value = meta.get("strength", 1.0)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value <= 1.0:
        raise InputError(path, f"strength {value!r} is not a number in [0, 1]", "meta.strength")
    return float(value)


def _keep_warp(path: Path, meta: dict) -> bool:
    """Whether the weights' views keep the warp (``meta.keep_warp``, chosen by an adaptation), else True."""
    value = meta.get("keep_warp", True)
    if not isinstance(value, bool):
        raise InputError(path, f"keep_warp {value!r} is not true or false", "meta.keep_warp")
    return value


def load_restorer(backend: str = "builtin", weights: str | os.PathLike | None = None, **flux_files):
    """``builtin`` (``weights``, else the shipped file with the shipped guided restorer, where there
    is one, for the geometry-guided methods) or ``flux`` (see :func:`.flux.load_flux`)."""
    if backend == "builtin":
        if weights:
            return load_builtin(weights)
        restorer = load_builtin(DEFAULT_WEIGHTS)
        if GUIDED_WEIGHTS.exists():
            restorer.guided = load_builtin(GUIDED_WEIGHTS)
        return restorer
    if backend == "flux":
        from .flux import load_flux

        return load_flux(**flux_files)
    raise ValueError(f"unknown restorer backend {backend!r} (expected 'builtin' or 'flux')")
