"""Denoiser evaluations on overlapping tiles, batched within a memory budget.

Tiling is applied per denoiser evaluation, inside each sampler step: the state ``z_t``, the
noise schedule and every random draw stay those of the whole image, and only the network call
``velocity(z_t, t, cond_left, cond_right)`` is cut into tiles (the two conditions cropped to the
same window), whose outputs are blended back with smooth weights. The Euler update, RePaint's
reset and the averaging of samples then act on the full image exactly as without tiles.

Plan, from the cheapest to the most intrusive (:func:`plan_tiles`):

1. the whole batch (samples x image) fits the budget: one call, bit-identical to no tiling;
2. one sample of the whole image fits: the batch is cut into chunks of samples, still the same
   computation per sample (every layer of the UNet, GroupNorm included, acts per sample);
3. otherwise the image is cut into tiles of ``tile`` pixels a side overlapping by at least
   ``overlap``, and (sample, tile) pairs are stacked ``batch`` at a time.

Tile origins are multiples of the network's downsampling factor (8 for the shipped UNet), so each
tile sees the same stride-2 sampling phase as the full image; a tile at the right or bottom edge
ends at the image edge and may be up to ``multiple - 1`` pixels longer than ``tile``, padded by
the network as the full image is. Blending: along each axis, where two neighbouring tiles overlap,
the earlier one falls and the later one rises over the whole overlap with a raised cosine
``sin^2(pi/2 (k + 1/2) / R)`` (the two sum to 1), weights are zero outside a tile's own part, and
the 2-D weight is the product of the two axes' weights divided by the sum over all tiles, so the
weights sum to 1 at every pixel (to float rounding) also where three tiles meet.

What tiling changes: the UNet's GroupNorm layers normalise over the part of the image they see,
so a tile's output differs from the same window of the full-image output by more than the
missing context at its border. The shipped restorer is trained on 64x64 crops, so tiles of a few
hundred pixels are as close to its training inputs as the full frame is (the test suite bounds
tiled against untiled output and checks that the error at tile borders is no larger than inside).

Memory model (measured, not computed): peak resident memory of one forward of the shipped UNet
(width 24) under ``torch.no_grad`` on the CPU, by the process's peak-RSS high-water mark reset
before the call (``/proc/self/clear_refs``), at 256x256 (128 MB) and 512x512 (414 MB) with one
sample, fits ``40 MB + 1460 bytes per pixel per sample`` (checked at 1024x512: 774 MB measured,
805 MB modelled; 256x256 with 4 samples: 414 MB, as 512x512 with one). :func:`measure_forward_bytes`
repeats the measurement for any restorer. Other widths scale the per-pixel term linearly.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

GIB = 1024**3
# Measured peak of one shipped-UNet forward (see the module docstring).
BUILTIN_BYTES_PER_PIXEL = 1460.0
BUILTIN_FIXED_BYTES = 40e6
BUILTIN_WIDTH = 24
# Full-image tensors a sampler holds beside the forward (state, conditions, init, velocity,
# the blended output and its weights): this many float32 copies of the batch's latent.
RESIDENT_COPIES = 8

DEFAULT_TILE = 256
DEFAULT_OVERLAP = 32


@dataclass(frozen=True)
class TileOptions:
    """How a denoiser is evaluated: ``max_memory_gib`` None means always in one piece (no limit)."""

    max_memory_gib: float | None = None
    tile: int = DEFAULT_TILE  # target tile side, in latent pixels (pixels for the built-in model)
    overlap: int = DEFAULT_OVERLAP  # least overlap of neighbouring tiles
    bytes_per_pixel: float | None = None  # per sample and latent pixel; None: from the model
    fixed_bytes: float | None = None


UNTILED = TileOptions()


@dataclass(frozen=True)
class Tile:
    y0: int
    y1: int
    x0: int
    x1: int

    @property
    def shape(self) -> tuple[int, int]:
        return self.y1 - self.y0, self.x1 - self.x0


@dataclass
class TilePlan:
    """``tiles`` (one covering the image when untiled) and ``batch``: items per forward."""

    height: int
    width: int
    tiles: list[Tile]
    batch: int
    forward_bytes: float  # modelled peak of one forward of ``batch`` items of the largest tile

    @property
    def untiled(self) -> bool:
        return len(self.tiles) == 1


def _round_up(n: int, m: int) -> int:
    return -(-n // m) * m


def axis_origins(length: int, tile: int, overlap: int, multiple: int = 1) -> list[tuple[int, int]]:
    """``(start, end)`` windows covering ``[0, length)``: starts are multiples of ``multiple``,
    neighbours overlap by at least ``overlap``, the last ends at ``length``; every window is at
    least ``tile`` long (except a single one when ``length <= tile``)."""
    m = max(1, int(multiple))
    tile = max(m, (int(tile) // m) * m)
    overlap = min(_round_up(max(0, int(overlap)), m), tile - m)
    if length <= tile:
        return [(0, length)]
    last = ((length - tile) // m) * m  # the last start: a multiple of m, its window >= tile
    if last == 0:
        return [(0, length)]  # one window, less than ``multiple`` pixels longer than ``tile``
    stride = tile - overlap  # the longest step that keeps the overlap; a multiple of m
    n = 1 + math.ceil(last / stride)
    starts = [m * ((i * (last // m)) // (n - 1)) for i in range(n)]
    return [(s, s + tile if i < n - 1 else length) for i, s in enumerate(starts)]


def make_tiles(height: int, width: int, tile: int, overlap: int, multiple: int = 1) -> list[Tile]:
    ys = axis_origins(height, tile, overlap, multiple)
    xs = axis_origins(width, tile, overlap, multiple)
    return [Tile(y0, y1, x0, x1) for y0, y1 in ys for x0, x1 in xs]


def _ramp(n: int) -> np.ndarray:
    """Raised cosine rising over ``n`` pixels, sampled at pixel centres: ``r[k] + r[n-1-k] = 1``."""
    return np.sin(0.5 * np.pi * (np.arange(n) + 0.5) / n) ** 2


def axis_weights(windows: list[tuple[int, int]]) -> list[np.ndarray]:
    """Per window, its 1-D weight (float64): rising over the overlap with the previous window,
    falling over the overlap with the next, 1 between."""
    out = []
    for i, (s, e) in enumerate(windows):
        w = np.ones(e - s)
        if i > 0:
            ps, pe = windows[i - 1]
            n = pe - s
            w[:n] = np.minimum(w[:n], _ramp(n))
        if i < len(windows) - 1:
            ns, ne = windows[i + 1]
            n = e - ns
            w[ns - s:] = np.minimum(w[ns - s:], 1.0 - _ramp(n))
        out.append(w)
    return out


def blend_weights(height: int, width: int, tiles: list[Tile]) -> list[np.ndarray]:
    """Per tile, its [h, w] blending weight (float64); summed over tiles, 1 at every pixel."""
    ys = sorted({(t.y0, t.y1) for t in tiles})
    xs = sorted({(t.x0, t.x1) for t in tiles})
    wy = dict(zip(ys, axis_weights(ys), strict=True))
    wx = dict(zip(xs, axis_weights(xs), strict=True))
    raw = [np.outer(wy[t.y0, t.y1], wx[t.x0, t.x1]) for t in tiles]
    total = np.zeros((height, width))
    for t, w in zip(tiles, raw, strict=True):
        total[t.y0:t.y1, t.x0:t.x1] += w
    if not (total > 0).all():
        raise AssertionError("tiles leave pixels without weight")
    return [w / total[t.y0:t.y1, t.x0:t.x1] for t, w in zip(tiles, raw, strict=True)]


def model_multiple(restorer) -> int:
    """The spatial factor tile origins must be multiples of (the UNet's downsampling)."""
    net = getattr(restorer, "net", None)
    return int(getattr(net, "multiple", None) or getattr(restorer, "multiple", 1) or 1)


def forward_cost(restorer, options: TileOptions = UNTILED) -> tuple[float, float]:
    """``(fixed bytes, bytes per latent pixel per sample)`` of one forward of ``restorer``."""
    if options.bytes_per_pixel is not None:
        return float(options.fixed_bytes or 0.0), float(options.bytes_per_pixel)
    cost = getattr(restorer, "forward_bytes", None)
    if cost is not None:
        return cost
    net = getattr(restorer, "net", None)
    width = getattr(getattr(net, "config", None), "width", BUILTIN_WIDTH)
    fixed = BUILTIN_FIXED_BYTES if options.fixed_bytes is None else float(options.fixed_bytes)
    return fixed, BUILTIN_BYTES_PER_PIXEL * width / BUILTIN_WIDTH


def plan_tiles(
    shape: tuple[int, ...],
    budget_bytes: float | None,
    bytes_per_pixel: float,
    fixed_bytes: float = 0.0,
    *,
    tile: int = DEFAULT_TILE,
    overlap: int = DEFAULT_OVERLAP,
    multiple: int = 1,
) -> TilePlan:
    """Tiles and items per forward for a [B, C, H, W] batch within ``budget_bytes`` (None: no limit).

    The budget pays for the full-image tensors the sampler holds (``RESIDENT_COPIES`` float32
    copies of the batch) and one forward (``fixed_bytes + bytes_per_pixel`` x pixels x items,
    pixels padded to ``multiple``). At least one item of one tile always runs, whatever the budget.
    """
    b, c, h, w = (int(s) for s in shape)

    def cost(th: int, tw: int, n: int) -> float:
        return fixed_bytes + bytes_per_pixel * _round_up(th, multiple) * _round_up(tw, multiple) * n

    whole = [Tile(0, h, 0, w)]
    if budget_bytes is None:
        return TilePlan(h, w, whole, b, cost(h, w, b))
    avail = float(budget_bytes) - RESIDENT_COPIES * 4.0 * b * c * h * w
    if cost(h, w, 1) <= avail:
        n = max(1, min(b, int((avail - fixed_bytes) // (cost(h, w, 1) - fixed_bytes))))
        return TilePlan(h, w, whole, n, cost(h, w, n))
    tiles = make_tiles(h, w, tile, overlap, multiple)
    th = max(t.shape[0] for t in tiles)
    tw = max(t.shape[1] for t in tiles)
    per_item = cost(th, tw, 1) - fixed_bytes
    n = max(1, min(b * len(tiles), int((avail - fixed_bytes) // per_item)))
    return TilePlan(h, w, tiles, n, cost(th, tw, n))


def plan_for(restorer, shape, options: TileOptions) -> TilePlan:
    fixed, bpp = forward_cost(restorer, options)
    budget = None if options.max_memory_gib is None else options.max_memory_gib * GIB
    return plan_tiles(shape, budget, bpp, fixed, tile=options.tile, overlap=options.overlap,
                      multiple=model_multiple(restorer))


Denoiser = Callable[..., torch.Tensor]
"""``(z_t [B,C,H,W], t [B], *conditions [B,C',H,W]) -> [B,C,H,W]``."""


def tiled_call(fn: Denoiser, plan: TilePlan, z: torch.Tensor, t: torch.Tensor, *conds: torch.Tensor) -> torch.Tensor:
    """``fn(z, t, *conds)`` evaluated by ``plan``: the same result in one piece when the plan
    holds one tile and the batch fits, else blended over tiles / concatenated over samples."""
    b = z.shape[0]
    if plan.untiled:
        if plan.batch >= b:
            return fn(z, t, *conds)
        return torch.cat([fn(z[i:i + plan.batch], t[i:i + plan.batch], *(c[i:i + plan.batch] for c in conds))
                          for i in range(0, b, plan.batch)])
    weights = [torch.from_numpy(w).to(z.dtype) for w in blend_weights(plan.height, plan.width, plan.tiles)]
    out = torch.zeros_like(z)
    by_shape: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for j, tile in enumerate(plan.tiles):
        for i in range(b):
            by_shape.setdefault(tile.shape, []).append((i, j))
    for items in by_shape.values():
        for k in range(0, len(items), plan.batch):
            chunk = items[k:k + plan.batch]

            def crop(x: torch.Tensor, chunk=chunk) -> torch.Tensor:
                return torch.stack([x[i, :, plan.tiles[j].y0:plan.tiles[j].y1, plan.tiles[j].x0:plan.tiles[j].x1]
                                    for i, j in chunk])

            v = fn(crop(z), torch.stack([t[i] for i, _ in chunk]), *(crop(c) for c in conds))
            for (i, j), vi in zip(chunk, v, strict=True):
                tl = plan.tiles[j]
                out[i, :, tl.y0:tl.y1, tl.x0:tl.x1] += weights[j] * vi
    return out


def tiled_velocity(restorer, shape, options: TileOptions):
    """``restorer.velocity`` with the same signature, evaluated on tiles per ``options``."""
    plan = plan_for(restorer, shape, options)

    def velocity(z_t, t, cond_left, cond_right, guide=None):
        conds = (cond_left, cond_right) if guide is None else (cond_left, cond_right, guide)
        if tuple(z_t.shape) != tuple(shape):
            return tiled_call(restorer.velocity, plan_for(restorer, z_t.shape, options), z_t, t, *conds)
        return tiled_call(restorer.velocity, plan, z_t, t, *conds)

    velocity.plan = plan
    return velocity


def measure_forward_bytes(restorer, sizes=((256, 256), (512, 512))) -> tuple[float, float]:
    """``(fixed bytes, bytes per pixel)`` fitted to the peak-RSS rise of one forward at two
    sizes (Linux: resets the high-water mark through ``/proc/self/clear_refs``). Memory the
    allocator kept from earlier calls is counted as free, so run it in a fresh process."""

    def status(key: str) -> int:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(key):
                    return int(line.split()[1]) * 1024
        raise OSError(f"{key} not in /proc/self/status")

    c = getattr(restorer.latent, "channels", 3)
    points = []
    with torch.no_grad():
        for h, w in sizes:
            z = torch.randn(1, c, h, w)
            t = torch.full((1,), 0.5)
            with open("/proc/self/clear_refs", "w") as f:
                f.write("5")
            base = status("VmRSS")
            restorer.velocity(z, t, z, z)
            points.append((h * w, status("VmHWM") - base))
    (p0, b0), (p1, b1) = points
    slope = (b1 - b0) / (p1 - p0)
    return b0 - slope * p0, slope
