"""Small learnt parameters beside the Gaussians (shadow layers, exposure transforms) saved with
their Adam moments, so a resumed fit continues them exactly where it stopped."""

from __future__ import annotations

from pathlib import Path

import torch


def save_params(path: Path, params: dict[str, torch.nn.Parameter], opt: torch.optim.Adam) -> None:
    """Each parameter as ``<name>`` and its Adam state as ``<name>.exp_avg`` and so on."""
    from safetensors.torch import save_file

    from ..io.atomic import atomic_path

    tensors = {}
    for name, p in params.items():
        tensors[name] = p.detach()
        for key, value in opt.state.get(p, {}).items():
            if key in ("exp_avg", "exp_avg_sq", "step"):
                tensors[f"{name}.{key}"] = value.reshape(-1) if key == "step" else value
    with atomic_path(Path(path)) as tmp:
        save_file({k: v.contiguous() for k, v in tensors.items()}, str(tmp))


def load_params(path: Path, params: dict[str, torch.nn.Parameter], opt: torch.optim.Adam) -> None:
    """Continue from :func:`save_params`' file (parameters it lacks keep their start)."""
    from safetensors.torch import load_file

    saved = load_file(str(path))
    for name, p in params.items():
        if name not in saved:
            continue
        with torch.no_grad():
            p.copy_(saved[name])
        if f"{name}.step" in saved:
            opt.state[p] = {"step": saved[f"{name}.step"].reshape(()), "exp_avg": saved[f"{name}.exp_avg"],
                            "exp_avg_sq": saved[f"{name}.exp_avg_sq"]}
