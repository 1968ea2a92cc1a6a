"""Small learnt parameters beside the Gaussians (shadow layers, exposure transforms): their own
Adam, stepped with the fit, and saved with its moments so a resumed fit continues them exactly
where it stopped."""

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


class SideParameters:
    """What a fit steps and checkpoints beside its Gaussians: subclasses set ``opt`` (None: nothing
    to fit) and ``checkpoint_file``, and name their parameters in :meth:`params`."""

    checkpoint_file: str
    opt: torch.optim.Adam | None
    start: int = 0  # the first iteration whose gradient is applied

    def params(self) -> dict[str, torch.nn.Parameter]:
        raise NotImplementedError

    def zero_grad(self) -> None:
        if self.opt is not None:
            self.opt.zero_grad(set_to_none=True)

    def step_at(self, it: int) -> None:
        """Apply iteration ``it``'s gradient, from ``start`` on."""
        if self.opt is not None and it >= self.start:
            self.opt.step()

    def checkpoint(self, folder: Path) -> None:
        """The parameters and their Adam moments in ``folder/<checkpoint_file>``."""
        save_params(Path(folder) / self.checkpoint_file, self.params(), self.opt)

    def resume(self, folder: Path) -> None:
        """Continue from :meth:`checkpoint`'s file, where there is one."""
        if (Path(folder) / self.checkpoint_file).is_file():
            load_params(Path(folder) / self.checkpoint_file, self.params(), self.opt)
