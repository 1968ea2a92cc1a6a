"""Compressed splat PLY (SuperSplat / PlayCanvas ``.compressed.ply``), decoded to Gaussians.

Splats come in chunks of 256 that share float32 bounds (element ``chunk``) for position,
log-scale and, in newer files, colour. Each splat (element ``vertex``) is four uint32 words:
position and log-scale as 11-10-11-bit fractions of the chunk's bounds; rotation as the three
smallest quaternion components (10 bits each, times sqrt(2)/2 folded into [0, 1]) and the index
of the largest in the top 2 bits, in ``rot_0..rot_3`` order (wxyz); colour as RGBA 8-8-8-8, where
RGB is the DC colour ``SH_C0 f_dc + 0.5`` and A is the activated opacity. An optional element
``sh`` holds ``f_rest_*`` as uint8 spanning [-4, 4]. The format is lossy: this returns the
quantized values. numpy only.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..gaussians import SH_C0, Gaussians, sh_degree_from_count

CHUNK_SIZE = 256
PACKED = ("packed_position", "packed_rotation", "packed_scale", "packed_color")
BOUNDS = tuple(f"{m}_{a}" for m in ("min", "max") for a in "xyz") + tuple(
    f"{m}_scale_{a}" for m in ("min", "max") for a in "xyz")
COLOUR_BOUNDS = tuple(f"{m}_{c}" for m in ("min", "max") for c in "rgb")
# Alpha is stored in 8 bits; 0 and 255 would be infinite logits. Half a step in from either end
# keeps them finite and on the same side of the renderer's 1/255 visibility threshold.
_ALPHA_EDGE = 0.5 / 255.0


def is_compressed(element_names: list[str], vertex_properties: list[str]) -> bool:
    return "chunk" in element_names and "packed_position" in vertex_properties


def check_header(path: Path, elements: dict[str, tuple[int, list]]) -> None:
    """The elements of a compressed splat file, from its header alone (``name: (count,
    [(property, type), ...])``): the packed words are 32-bit unsigned, the chunks hold every
    splat and carry their bounds, the ``sh`` rows match the splats. Nothing is allocated."""
    n, vertex = elements["vertex"]
    types = dict(vertex)
    missing = [p for p in PACKED if p not in types]
    if missing:
        raise InputError(path, f"compressed splat file without {', '.join(missing)}", "element vertex")
    wrong = [p for p in PACKED if types[p] != "u4"]
    if wrong:
        raise InputError(path, f"packed words must be uint32: {', '.join(wrong)}", "element vertex")
    chunks, chunk_props = elements["chunk"]
    if chunks * CHUNK_SIZE < n:
        raise InputError(path, f"{chunks} chunks hold at most {chunks * CHUNK_SIZE} splats, the file has {n}",
                         "element chunk")
    names = [p for p, _ in chunk_props]
    missing = [b for b in BOUNDS if b not in names]
    if missing:
        raise InputError(path, f"compressed splat file without {', '.join(missing)}", "element chunk")
    if any(isinstance(t, tuple) for _, t in chunk_props):
        raise InputError(path, "list properties are not allowed in chunks", "element chunk")
    if "sh" in elements:
        rows, sh_props = elements["sh"]
        if rows != n:
            raise InputError(path, f"element sh has {rows} rows for {n} splats", "element sh")
        expected = [f"f_rest_{i}" for i in range(len(sh_props))]
        if [p for p, _ in sh_props] != expected or len(sh_props) not in (9, 24, 45):
            raise InputError(path, "expected f_rest_0..f_rest_M-1 with M = 9, 24 or 45", "element sh")


def _unorm(words: np.ndarray, shift: int, bits: int) -> np.ndarray:
    return ((words >> np.uint32(shift)) & np.uint32((1 << bits) - 1)).astype(np.float64) / ((1 << bits) - 1)


def _unpack_11_10_11(words: np.ndarray) -> np.ndarray:
    return np.stack([_unorm(words, 21, 11), _unorm(words, 11, 10), _unorm(words, 0, 11)], axis=1)


def _unpack_rotation(words: np.ndarray) -> np.ndarray:
    small = np.stack([_unorm(words, 20, 10), _unorm(words, 10, 10), _unorm(words, 0, 10)], axis=1)
    small = (small - 0.5) * np.sqrt(2.0)
    largest = np.sqrt(np.maximum(0.0, 1.0 - np.sum(small * small, axis=1)))
    which = (words >> np.uint32(30)).astype(np.int64)
    q = np.empty((words.shape[0], 4))
    rows = np.arange(words.shape[0])
    q[rows, which] = largest
    others = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])[which]
    q[rows[:, None], others] = small
    return q


def _dequantize_sh(values: np.ndarray) -> np.ndarray:
    n = (values.astype(np.float64) + 0.5) / 256.0
    n[values == 0] = 0.0
    n[values == 255] = 1.0
    return (n - 0.5) * 8.0


def _columns(path: Path, table: np.ndarray, names: tuple[str, ...], element: str) -> np.ndarray:
    missing = [n for n in names if n not in (table.dtype.names or ())]
    if missing:
        raise InputError(path, f"compressed splat file without {', '.join(missing)}", f"element {element}")
    return np.stack([table[n].astype(np.float64) for n in names], axis=1)


def decode(path: Path, tables: dict[str, np.ndarray]) -> Gaussians:
    """Gaussians from the ``chunk``, ``vertex`` and optional ``sh`` tables of a compressed PLY."""
    vertex, chunk = tables["vertex"], tables["chunk"]
    missing = [n for n in PACKED if n not in (vertex.dtype.names or ())]
    if missing:
        raise InputError(path, f"compressed splat file without {', '.join(missing)}", "element vertex")
    n = vertex.shape[0]
    if chunk.shape[0] * CHUNK_SIZE < n:
        raise InputError(path, f"{chunk.shape[0]} chunks hold at most {chunk.shape[0] * CHUNK_SIZE} splats, "
                               f"the file has {n}", "element chunk")
    bounds = _columns(path, chunk, BOUNDS, "chunk")[np.arange(n) // CHUNK_SIZE]
    words = {name: vertex[name].astype(np.uint32) for name in PACKED}

    def lerp(lo: np.ndarray, hi: np.ndarray, t: np.ndarray) -> np.ndarray:
        return lo * (1.0 - t) + hi * t

    means = lerp(bounds[:, 0:3], bounds[:, 3:6], _unpack_11_10_11(words["packed_position"]))
    log_scales = lerp(bounds[:, 6:9], bounds[:, 9:12], _unpack_11_10_11(words["packed_scale"]))
    rgba = np.stack([_unorm(words["packed_color"], s, 8) for s in (24, 16, 8, 0)], axis=1)
    rgb = rgba[:, :3]
    if all(c in (chunk.dtype.names or ()) for c in COLOUR_BOUNDS):  # newer files: colour bounds per chunk
        cb = _columns(path, chunk, COLOUR_BOUNDS, "chunk")[np.arange(n) // CHUNK_SIZE]
        rgb = lerp(cb[:, 0:3], cb[:, 3:6], rgb)
    alpha = np.clip(rgba[:, 3], _ALPHA_EDGE, 1.0 - _ALPHA_EDGE)

    rest = np.zeros((n, 0, 3))
    if "sh" in tables:
        sh_table = tables["sh"]
        names = list(sh_table.dtype.names or ())
        if sh_table.shape[0] != n:
            raise InputError(path, f"element sh has {sh_table.shape[0]} rows for {n} splats", "element sh")
        expected = [f"f_rest_{i}" for i in range(len(names))]
        if names != expected or len(names) not in (9, 24, 45):
            raise InputError(path, "expected f_rest_0..f_rest_M-1 with M = 9, 24 or 45", "element sh")
        rest = _dequantize_sh(np.stack([sh_table[nm] for nm in names], axis=1)).reshape(n, 3, -1).transpose(0, 2, 1)
    sh = np.concatenate([((rgb - 0.5) / SH_C0)[:, None, :], rest], axis=1)
    sh_degree_from_count(sh.shape[1])
    return Gaussians(
        means=means.astype(np.float32),
        quats=_unpack_rotation(words["packed_rotation"]).astype(np.float32),
        log_scales=log_scales.astype(np.float32),
        opacity_logits=np.log(alpha / (1.0 - alpha)).astype(np.float32),
        sh=sh.astype(np.float32),
    )
