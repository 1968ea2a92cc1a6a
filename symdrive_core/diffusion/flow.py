"""Rectified-flow schedule and Euler sampler shared by every backend.

Forward process ``z_t = (1 - t) x0 + t eps``; the network predicts the velocity
``v = eps - x0``, so one Euler step from ``t`` to ``s < t`` is ``z_s = z_t + (s - t) v``.
Inference may start part-way down the schedule (the paper's position-accurate initialisation):
at step ``N_start`` of ``N`` the state is ``(1 - sigma) z_cond + sigma eps`` with
``sigma = t[N_start]``, so the structure of ``z_cond`` survives while fine detail is re-drawn.
Every random draw goes through an explicit ``torch.Generator``: same seed, same image.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch

Velocity = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]
"""``(z_t [B,...], t [B]) -> v [B,...]``: the conditions are bound in by the caller."""


def noised(x0: torch.Tensor, eps: torch.Tensor, t) -> torch.Tensor:
    """``(1 - t) x0 + t eps`` with ``t`` a number or a per-sample tensor [B]."""
    t = _broadcast(t, x0)
    return (1.0 - t) * x0 + t * eps


def velocity_target(x0: torch.Tensor, eps: torch.Tensor) -> torch.Tensor:
    return eps - x0


def start_velocity_target(x0: torch.Tensor, x_start: torch.Tensor, eps: torch.Tensor, t) -> torch.Tensor:
    """``(z_t - x0) / t`` for ``z_t = (1 - t) x_start + t eps``: the velocity whose Euler step
    from ``t`` to 0 lands on ``x0``. Equals :func:`velocity_target` when ``x_start`` is ``x0``;
    ``t`` must be positive wherever the two differ."""
    t = _broadcast(t, x0)
    gap = x_start - x0
    return velocity_target(x0, eps) + torch.where(gap == 0, 0.0, (1.0 - t) / t * gap)


def _broadcast(t, like: torch.Tensor) -> torch.Tensor | float:
    if isinstance(t, torch.Tensor) and t.ndim == 1:
        return t.reshape(-1, *([1] * (like.ndim - 1))).to(like.dtype)
    return t


def time_shift(t: torch.Tensor, mu: float) -> torch.Tensor:
    """Flux's resolution-dependent shift ``e^mu / (e^mu + 1/t - 1)``; identity at ``mu = 0``."""
    if mu == 0.0:
        return t
    out = torch.zeros_like(t)
    pos = t > 0
    out[pos] = math.exp(mu) / (math.exp(mu) + (1.0 / t[pos] - 1.0))
    return out


def timesteps(steps: int, mu: float = 0.0) -> torch.Tensor:
    """``steps + 1`` noise levels from 1 down to 0 (float64 so long chains stay exact)."""
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    return time_shift(torch.linspace(1.0, 0.0, steps + 1, dtype=torch.float64), mu)


def start_state(
    z_cond: torch.Tensor, ts: torch.Tensor, n_start: int, generator: torch.Generator
) -> torch.Tensor:
    """The state at step ``n_start``: ``(1 - sigma) z_cond + sigma eps`` (pure noise at 0)."""
    if not 0 <= n_start < len(ts) - 1:
        raise ValueError(f"n_start must lie in [0, {len(ts) - 2}] for {len(ts) - 1} steps, got {n_start}")
    eps = torch.randn(z_cond.shape, generator=generator, dtype=z_cond.dtype)
    return noised(z_cond, eps, float(ts[n_start]))


def euler(
    velocity: Velocity,
    z: torch.Tensor,
    ts: torch.Tensor,
    *,
    start: int = 0,
    after_step: Callable[[torch.Tensor, int], torch.Tensor] | None = None,
    progress: bool = False,
) -> torch.Tensor:
    """Integrate from ``ts[start]`` to ``ts[-1]``; ``after_step(z, i)`` may edit the state at ``ts[i]``
    (RePaint's known-region reset)."""
    from tqdm import tqdm

    batch = z.shape[0]
    for i in tqdm(range(start, len(ts) - 1), desc="sample", unit="step", disable=not progress, leave=False):
        t, s = float(ts[i]), float(ts[i + 1])
        v = velocity(z, torch.full((batch,), t, dtype=z.dtype))
        z = z + (s - t) * v
        if after_step is not None:
            z = after_step(z, i + 1)
    return z


def training_times(
    batch: int, generator: torch.Generator, t_max: float = 1.0, full_fraction: float = 0.0
) -> torch.Tensor:
    """Noise levels for one batch: uniform on ``[0, t_max]``, except a ``full_fraction`` share
    drawn on all of ``[0, 1]``. Sampling that starts at step ``N_start`` only ever evaluates the
    model at ``t <= ts[N_start]``, so training can spend its steps there and keep a little
    full-range coverage for sampling from pure noise."""
    u = torch.rand(batch, generator=generator, dtype=torch.float32)
    full = torch.rand(batch, generator=generator) < full_fraction
    return torch.where(full, u, u * float(t_max))


def flow_loss(
    velocity: Velocity,
    x0: torch.Tensor,
    generator: torch.Generator,
    *,
    t_max: float = 1.0,
    full_fraction: float = 0.0,
    weight: Callable[[torch.Tensor], torch.Tensor] | None = None,
    x_start: torch.Tensor | None = None,
    start_t_min: float = 0.1,
) -> torch.Tensor:
    """Mean squared velocity error (the paper's training objective) at ``t`` drawn by
    :func:`training_times` (uniform on ``[0, 1]`` by default), optionally weighted per sample.

    ``x_start`` (default ``x0``) is what the noisy state is made from, ``z_t = (1 - t) x_start +
    t eps``, with the target :func:`start_velocity_target` still leading to ``x0``: samples whose
    start differs from ``x0`` (a degraded render) learn to repair it, as sampling from ``N_start``
    must. Their ``t`` is mapped to ``start_t_min + (1 - start_t_min) t``, away from 0, where no
    step is left to repair anything in."""
    if t_max >= 1.0 and full_fraction == 0.0:
        t = torch.rand(x0.shape[0], generator=generator, dtype=x0.dtype)
    else:
        t = training_times(x0.shape[0], generator, t_max, full_fraction).to(x0.dtype)
    eps = torch.randn(x0.shape, generator=generator, dtype=x0.dtype)
    if x_start is None:
        v = velocity(noised(x0, eps, t), t)
        target = velocity_target(x0, eps)
    else:
        repair = (x_start != x0).flatten(1).any(1)
        t = torch.where(repair, start_t_min + (1.0 - start_t_min) * t, t)
        v = velocity(noised(x_start, eps, t), t)
        target = start_velocity_target(x0, x_start, eps, t)
    err = ((v - target) ** 2).flatten(1).mean(1)
    if weight is not None:
        err = err * weight(t)
    return err.mean()


def renoise(z_t: torch.Tensor, t: float, t_up: float, generator: torch.Generator) -> torch.Tensor:
    """Go back up from level ``t`` to ``t_up > t`` keeping the marginals exact:
    ``z' = a z_t + sqrt(t_up^2 - (a t)^2) eps'`` with ``a = (1 - t_up) / (1 - t)``."""
    if not 0.0 <= t < t_up <= 1.0:
        raise ValueError(f"renoise needs 0 <= t < t_up <= 1, got t={t}, t_up={t_up}")
    a = (1.0 - t_up) / (1.0 - t)
    b = math.sqrt(max(t_up**2 - (a * t) ** 2, 0.0))
    eps = torch.randn(z_t.shape, generator=generator, dtype=z_t.dtype)
    return a * z_t + b * eps
