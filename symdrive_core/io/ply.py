"""INRIA 3DGS splat PLY files, read and written with numpy structured arrays.

Reads binary little/big-endian and ascii; SH degree 0..3 is inferred from the number of
``f_rest_*`` properties (stored channel-major: all of red's higher coefficients, then green's,
then blue's). Properties the format does not define are kept in ``Gaussians.extra``; Mip-Splatting's
``filter_3D`` is folded into scales and opacities (:func:`fold_3d_filter`) and 2DGS surfels (two
scales) become flat Gaussians. Compressed
files (``chunk`` + packed ``vertex``) are decoded by :mod:`.compressed_ply`. numpy only.
"""

from __future__ import annotations

import os
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..gaussians import Gaussians, sh_coeff_count
from . import compressed_ply, open_regular
from .atomic import atomic_path

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_FORMATS = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": "ascii"}
REQUIRED = ("x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
            "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3")
_KNOWN = set(REQUIRED) | {"nx", "ny", "nz"}
_F_REST = re.compile(r"^f_rest_(\d+)$")
# 2DGS surfels store two scales; read as 3D Gaussians this much thinner than their smaller axis.
SURFEL_THICKNESS = 1e-3
# Mip-Splatting's 3D smoothing filter (per-Gaussian std. dev. in world units), by either spelling.
_FILTER_3D = ("filter_3D", "filter_3d")


@dataclass
class _Element:
    name: str
    count: int
    properties: list[tuple[str, str | tuple[str, str]]]  # (name, type) or (name, (count_t, item_t))

    @property
    def has_lists(self) -> bool:
        return any(isinstance(t, tuple) for _, t in self.properties)


@dataclass
class PlyHeader:
    fmt: str  # "<", ">" or "ascii"
    elements: list[_Element]
    data_offset: int

    def element(self, name: str) -> _Element | None:
        return next((e for e in self.elements if e.name == name), None)


# Bounds checked before anything is allocated: a header is a few kB; these leave room for
# any real file and stop a hostile one (a 100 MB "line", /dev/zero) from growing memory.
MAX_HEADER_LINE = 64 * 1024
MAX_HEADER_BYTES = 1024 * 1024


def _row_bytes(fmt: str, el: _Element) -> int:
    """The fewest bytes one row of ``el`` can take: exact without lists, a lower bound with
    them (an empty list is just its count); in ascii, one digit and a separator per value."""
    if fmt == "ascii":
        return 2 * len(el.properties)
    return sum(np.dtype(t[0] if isinstance(t, tuple) else t).itemsize for _, t in el.properties)


def _truncated(path, el: _Element, offset: int, row: int, size: int, exact: bool = True) -> InputError:
    need = offset + el.count * row
    have = max(0, (size - offset) // max(row, 1))
    rows = "vertices" if el.name == "vertex" else f"'{el.name}' rows"
    at_least = "" if exact else "at least "
    return InputError(
        path,
        f"truncated: header declares {el.count} {rows} ({at_least}{need} bytes with the header) "
        f"but the file has {size} bytes (room for {have} {rows})",
        f"element {el.name}",
    )


def read_header(path: str | os.PathLike) -> PlyHeader:
    """The header of a PLY file, checked against the file before any data is read.

    Only regular files are opened. Header lines longer than ``MAX_HEADER_LINE`` bytes, headers
    longer than ``MAX_HEADER_BYTES``, negative counts, duplicate elements or properties, and
    declared sizes the file cannot hold are :class:`InputError` naming the file and field.
    """
    path = Path(path)
    with open_regular(path) as f:
        size = os.fstat(f.fileno()).st_size
        if f.readline(MAX_HEADER_LINE + 1).strip() != b"ply":
            raise InputError(path, "not a PLY file (first line is not 'ply')")
        fmt = None
        elements: list[_Element] = []
        while True:
            raw = f.readline(MAX_HEADER_LINE + 1)
            if not raw:
                raise InputError(path, "header has no 'end_header' line")
            if len(raw) > MAX_HEADER_LINE:
                raise InputError(path, f"header line longer than {MAX_HEADER_LINE} bytes", "header")
            if f.tell() > MAX_HEADER_BYTES:
                raise InputError(path, f"header longer than {MAX_HEADER_BYTES} bytes without 'end_header'",
                                 "header")
            words = raw.decode("ascii", errors="replace").split()
            if not words or words[0] in ("comment", "obj_info"):
                continue
            if words[0] == "end_header":
                break
            if words[0] == "format":
                if len(words) < 2 or words[1] not in _FORMATS:
                    raise InputError(path, f"unsupported format line {raw.strip()[:80]!r}", "header.format")
                fmt = _FORMATS[words[1]]
            elif words[0] == "element":
                try:
                    name, count = words[1], int(words[2])
                except (IndexError, ValueError):
                    raise InputError(path, f"bad element line {raw.strip()[:80]!r}", "header") from None
                if count < 0:
                    raise InputError(path, f"negative count {count}", f"element {name}")
                if any(e.name == name for e in elements):
                    raise InputError(path, "element declared twice", f"element {name}")
                elements.append(_Element(name, count, []))
            elif words[0] == "property":
                if not elements:
                    raise InputError(path, "property before any element", "header")
                el = elements[-1]
                try:
                    if words[1] == "list":
                        prop = (words[4], (_PLY_TYPES[words[2]], _PLY_TYPES[words[3]]))
                    else:
                        prop = (words[2], _PLY_TYPES[words[1]])
                except (IndexError, KeyError):
                    raise InputError(path, f"bad property line {raw.strip()[:80]!r}",
                                     f"element {el.name}") from None
                if any(n == prop[0] for n, _ in el.properties):
                    raise InputError(path, f"duplicate property {prop[0]!r}", f"element {el.name}")
                el.properties.append(prop)
        if fmt is None:
            raise InputError(path, "header has no format line", "header.format")
        header = PlyHeader(fmt, elements, f.tell())
    _check_sizes(path, header, size)
    return header


def _check_sizes(path: Path, header: PlyHeader, size: int) -> None:
    """Every declared element fits in the file: a declared size larger than the file is an
    error here, never an allocation later."""
    offset = header.data_offset
    for el in header.elements:
        if el.count and not el.properties:
            raise InputError(path, f"declares {el.count} rows with no properties", f"element {el.name}")
        row = _row_bytes(header.fmt, el)
        if header.fmt == "ascii":
            need = offset + max(0, el.count * row - 1)
            if need > size:
                rows = "vertices" if el.name == "vertex" else "rows"
                raise InputError(path, f"header declares {el.count} {rows} of {len(el.properties)} values, "
                                       f"more than the file's {size} bytes can hold", f"element {el.name}")
        else:
            need = offset + el.count * row
            if need > size:
                raise _truncated(path, el, offset, row, size, exact=not el.has_lists)
        offset = need


def check_ply(path: str | os.PathLike, kind: str = "splats") -> PlyHeader:
    """Check a PLY without reading its data: the header, the declared sizes against the file,
    and the properties a ``kind`` of file needs ("splats": a 3DGS or compressed splat file,
    "points": a coloured point cloud). ``symdrive validate`` runs this on every PLY it names."""
    path = Path(path)
    header = read_header(path)
    vertex = header.element("vertex")
    if vertex is None:
        raise InputError(path, "no 'vertex' element: not a point or splat file", "element vertex")
    if vertex.has_lists:
        raise InputError(path, "list properties in the vertex element are not supported", "element vertex")
    names = [n for n, _ in vertex.properties]
    if kind == "points":
        missing = [c for c in ("x", "y", "z") if c not in names]
        if missing:
            raise InputError(path, f"point cloud lacks {', '.join(missing)}", "element vertex")
    elif compressed_ply.is_compressed([e.name for e in header.elements], names):
        if header.fmt == "ascii":
            raise InputError(path, "compressed splat files are binary; this one says ascii", "header.format")
        compressed_ply.check_header(path, {e.name: (e.count, e.properties) for e in header.elements})
    else:
        _splat_layout(path, names)
    return header


def _splat_layout(path: Path, names: list[str]) -> tuple[bool, int]:
    """(2DGS surfels?, SH coefficients per channel) of a 3DGS vertex table with these properties."""
    surfels = "scale_2" not in names and {"scale_0", "scale_1"} <= set(names)  # a 2DGS file
    missing = [n for n in REQUIRED if n not in names and not (surfels and n == "scale_2")]
    if missing:
        kind = "not a 3DGS splat file" if len(missing) > 3 else "missing required property"
        raise InputError(path, f"{kind}: no {', '.join(missing)}", "element vertex")
    rest_idx = sorted(int(m.group(1)) for n in names if (m := _F_REST.match(n)))
    if rest_idx != list(range(len(rest_idx))):
        raise InputError(path, "f_rest_* properties are not numbered 0..M-1", "element vertex")
    if len(rest_idx) % 3:
        raise InputError(path, f"{len(rest_idx)} f_rest_* properties is not a multiple of 3", "f_rest")
    k = len(rest_idx) // 3 + 1
    degree = int(round(np.sqrt(k))) - 1
    if (degree + 1) ** 2 != k or degree > 3:
        raise InputError(path, f"{len(rest_idx)} f_rest_* properties matches no SH degree 0..3", "f_rest")
    return surfels, k


def read_vertex_table(path: Path, header: PlyHeader) -> np.ndarray:
    """The vertex element of a point or splat PLY (binary or ASCII) as one structured array."""
    vertex = header.element("vertex")
    if vertex is None:
        raise InputError(path, "no 'vertex' element: not a point or splat file", "element vertex")
    if vertex.has_lists:
        raise InputError(path, "list properties in the vertex element are not supported", "element vertex")
    if header.fmt == "ascii":
        return _read_ascii_vertices(path, header, vertex)
    return _read_binary_tables(path, header, ("vertex",))["vertex"]


def _read_binary_tables(path: Path, header: PlyHeader, wanted: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The tables of the elements named ``wanted`` of a binary PLY, in native byte order."""
    tables: dict[str, np.ndarray] = {}
    offset = header.data_offset
    with open_regular(path) as f:
        size = os.fstat(f.fileno()).st_size
        for el in header.elements:
            if len(tables) == len(wanted):
                break
            if el.has_lists:
                raise InputError(path, f"element '{el.name}' has list properties, which splat files do not use",
                                 f"element {el.name}")
            dtype = np.dtype([(n, header.fmt + t) for n, t in el.properties])
            need = offset + el.count * dtype.itemsize
            if el.name in wanted:
                if size < need:  # the file changed since its header was read
                    raise _truncated(path, el, offset, dtype.itemsize, size)
                f.seek(offset)
                table = np.fromfile(f, dtype=dtype, count=el.count)
                if table.shape[0] != el.count:
                    raise _truncated(path, el, offset, dtype.itemsize, offset + table.nbytes)
                tables[el.name] = table if dtype.isnative else table.astype(dtype.newbyteorder("="))
            offset = need
    return tables


def _read_ascii_vertices(path: Path, header: PlyHeader, vertex: _Element) -> np.ndarray:
    with open_regular(path) as f:
        f.seek(header.data_offset)
        lines = f.read().decode("ascii", errors="replace").splitlines()
    skip = 0
    for el in header.elements:
        if el is vertex:
            break
        skip += el.count
    rows = [ln for ln in lines[skip: skip + vertex.count]]
    if len(rows) < vertex.count:
        raise InputError(path, f"header declares {vertex.count} vertices, file has {len(rows)} rows",
                         "element vertex")
    try:
        values = np.array([r.split() for r in rows], dtype=np.float64)
    except ValueError:
        raise InputError(path, "vertex rows have a varying number of values or non-numbers",
                         "element vertex") from None
    n_props = len(vertex.properties)
    if values.ndim != 2 or values.shape[1] != n_props:
        raise InputError(path, f"vertex rows must have {n_props} values", "element vertex")
    dtype = np.dtype([(n, t) for n, t in vertex.properties])
    table = np.empty(vertex.count, dtype=dtype)
    for i, (name, _) in enumerate(vertex.properties):
        table[name] = values[:, i]
    return table


def _stack(table: np.ndarray, names: list[str]) -> np.ndarray:
    """Columns ``names`` of the vertex table as one float32 [N, len(names)] array."""
    fields = table.dtype.fields
    if all(fields[n][0] == np.dtype("=f4") for n in table.dtype.names):
        # Homogeneous float32 rows (every 3DGS exporter writes these): one strided gather.
        flat = table.view(np.float32).reshape(table.shape[0], len(table.dtype.names))
        return flat[:, [table.dtype.names.index(n) for n in names]]
    out = np.empty((table.shape[0], len(names)), dtype=np.float32)
    for i, n in enumerate(names):
        out[:, i] = table[n]
    return out


def sh_rest_names(degree: int) -> list[str]:
    return [f"f_rest_{i}" for i in range(3 * (sh_coeff_count(degree) - 1))]


def read_splats(path: str | os.PathLike, *, drop_invalid: bool = False) -> Gaussians:
    """Read an INRIA 3DGS PLY into unactivated :class:`Gaussians`.

    Raises :class:`InputError` naming the file and the field for anything that is not a valid
    splat file. Non-finite values are an error unless ``drop_invalid`` drops those splats.
    """
    path = Path(path)
    header = read_header(path)
    table = read_vertex_table(path, header)
    names = list(table.dtype.names or ())
    if compressed_ply.is_compressed([e.name for e in header.elements], names):
        if header.fmt == "ascii":
            raise InputError(path, "compressed splat files are binary; this one says ascii", "header.format")
        compressed_ply.check_header(path, {e.name: (e.count, e.properties) for e in header.elements})
        wanted = ("chunk", "vertex", "sh") if header.element("sh") else ("chunk", "vertex")
        return _checked(path, compressed_ply.decode(path, _read_binary_tables(path, header, wanted)), drop_invalid)
    surfels, k = _splat_layout(path, names)
    degree = int(round(np.sqrt(k))) - 1

    n = table.shape[0]
    sh = np.empty((n, k, 3), dtype=np.float32)
    sh[:, 0, :] = _stack(table, ["f_dc_0", "f_dc_1", "f_dc_2"])
    if k > 1:
        rest = _stack(table, sh_rest_names(degree)).reshape(n, 3, k - 1)
        sh[:, 1:, :] = rest.transpose(0, 2, 1)
    normals = _stack(table, ["nx", "ny", "nz"]) if {"nx", "ny", "nz"} <= set(names) else None
    extra = {nm: np.ascontiguousarray(table[nm]) for nm in names
             if nm not in _KNOWN and nm not in _FILTER_3D and not _F_REST.match(nm)}
    log_scales = _surfel_log_scales(table) if surfels else _stack(table, ["scale_0", "scale_1", "scale_2"])
    opacity_logits = np.ascontiguousarray(table["opacity"], dtype=np.float32)
    filter_name = next((nm for nm in _FILTER_3D if nm in names), None)
    if filter_name:
        log_scales, opacity_logits = fold_3d_filter(log_scales, opacity_logits, table[filter_name])
    g = Gaussians(
        means=_stack(table, ["x", "y", "z"]),
        quats=_stack(table, ["rot_0", "rot_1", "rot_2", "rot_3"]),
        log_scales=log_scales,
        opacity_logits=opacity_logits,
        sh=sh,
        normals=normals,
        extra=extra,
    )
    return _checked(path, g, drop_invalid)


def _surfel_log_scales(table: np.ndarray) -> np.ndarray:
    """2DGS surfels as flat 3D Gaussians: a surfel's rotation columns are its two tangents and
    its normal, the same order a 3DGS rotation's axes have, so only the normal's scale is new."""
    two = _stack(table, ["scale_0", "scale_1"])
    return np.concatenate([two, two.min(axis=1, keepdims=True) + np.float32(np.log(SURFEL_THICKNESS))], axis=1)


def fold_3d_filter(log_scales: np.ndarray, opacity_logits: np.ndarray,
                   filter_3d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bake Mip-Splatting's 3D smoothing filter into plain 3DGS parameters.

    Its renderer convolves each Gaussian with an isotropic one of std. dev. ``filter_3d`` and
    keeps the integral: scales become sqrt(s^2 + f^2) and opacity is multiplied by
    sqrt(det(S^2) / det(S^2 + f^2)). Rendering the folded splats with any 3DGS renderer gives
    the image Mip-Splatting's own renderer gives; reading the file raw would not.
    """
    # All in log space, so that tiny and huge scales and saturated opacities stay finite.
    log_s2 = 2.0 * log_scales.astype(np.float64)
    with np.errstate(divide="ignore"):  # f = 0 is no filter: log 0 = -inf folds to nothing
        log_f2 = 2.0 * np.log(np.abs(np.asarray(filter_3d, dtype=np.float64))).reshape(-1, 1)
    log_filtered = np.logaddexp(log_s2, log_f2)
    log_coef = 0.5 * np.sum(log_s2 - log_filtered, axis=1)  # <= 0
    o = opacity_logits.astype(np.float64)
    log_alpha = -np.logaddexp(0.0, -o)
    # log(1 - coef * alpha), written as log((1 - coef) + coef * (1 - alpha))
    with np.errstate(divide="ignore"):
        log_one_minus = np.logaddexp(np.log(-np.expm1(log_coef)), log_coef - np.logaddexp(0.0, o))
    logits = log_coef + log_alpha - log_one_minus
    return (0.5 * log_filtered).astype(np.float32), logits.astype(np.float32)


def _checked(path: Path, g: Gaussians, drop_invalid: bool) -> Gaussians:
    """``g`` without non-finite splats (said, as a warning), or an error naming how many there are."""
    ok = g.finite_mask()
    bad = int(len(g) - ok.sum())
    if bad:
        if not drop_invalid:
            raise InputError(path, f"{bad} of {len(g)} splats have NaN or Inf values (`symdrive info "
                                   "--drop-invalid` describes the others)", "element vertex")
        warnings.warn(f"{path}: dropped {bad} of {len(g)} splats with NaN or Inf values", stacklevel=3)
        g = g.subset(ok)
    return g


def write_splats(path: str | os.PathLike, g: Gaussians, *, keep_extra: bool = True) -> None:
    """Write binary little-endian INRIA 3DGS PLY atomically."""
    n, k = len(g), g.sh.shape[1]
    fields = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    fields += sh_rest_names(g.sh_degree)
    fields += ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    extra = {name: v for name, v in g.extra.items() if keep_extra and v.shape == (n,)}
    dtype = [(f, "<f4") for f in fields] + [(name, v.dtype.newbyteorder("<").str) for name, v in extra.items()]
    table = np.empty(n, dtype=dtype)
    cols = {
        "x": g.means[:, 0], "y": g.means[:, 1], "z": g.means[:, 2],
        "f_dc_0": g.sh[:, 0, 0], "f_dc_1": g.sh[:, 0, 1], "f_dc_2": g.sh[:, 0, 2],
        "opacity": g.opacity_logits,
    }
    normals = g.normals if g.normals is not None else np.zeros((n, 3), np.float32)
    for i, c in enumerate("xyz"):
        cols[f"n{c}"] = normals[:, i]
    for i in range(3):
        cols[f"scale_{i}"] = g.log_scales[:, i]
    for i in range(4):
        cols[f"rot_{i}"] = g.quats[:, i]
    if k > 1:
        rest = g.sh[:, 1:, :].transpose(0, 2, 1).reshape(n, 3 * (k - 1))
        for i, name in enumerate(sh_rest_names(g.sh_degree)):
            cols[name] = rest[:, i]
    cols.update(extra)
    for name in table.dtype.names:
        table[name] = cols[name]
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {n}"]
    inv = {v: key for key, v in _PLY_TYPES.items() if key in ("char", "uchar", "short", "ushort", "int", "uint", "float", "double")}
    for name in table.dtype.names:
        header.append(f"property {inv[table.dtype[name].str[1:]]} {name}")
    header.append("end_header")
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        table.tofile(f)


def describe(path: str | os.PathLike, g: Gaussians | None = None) -> dict:
    """Summary for ``symdrive info``: count, SH degree, bounds, extra properties."""
    g = read_splats(path) if g is None else g
    lo, hi = g.bounds()
    return {
        "path": str(path),
        "count": len(g),
        "sh_degree": g.sh_degree,
        "bounds_min": [float(v) for v in lo],
        "bounds_max": [float(v) for v in hi],
        "has_normals": g.normals is not None,
        "extra_properties": sorted(g.extra),
    }
