"""The one reader of ``wlh.json``: a vehicle asset's box size (width, length, height) in metres.

Every form the project writes or documents is accepted:

* ``[w, l, h]``
* ``{"w": .., "l": .., "h": ..}`` (or ``"width"``, ``"length"``, ``"height"``)
* ``{"wlh": [w, l, h], ...}``, the form the core writes beside an asset (other keys, such as the
  ``splats`` and ``mesh`` file names, are returned by :func:`read_wlh_info`)

Sizes must be finite, positive and below :data:`MAX_SIZE_M`. Bad input raises
:class:`~symdrive_core.errors.InputError` naming the file and the field. Standard library only:
the Blender add-on bundles this module.
"""

from __future__ import annotations

import json
import math
import os

from ..errors import InputError

MAX_SIZE_M = 1000.0
NAMES = (("w", "width"), ("l", "length"), ("h", "height"))
FORMS = "[w, l, h], {\"w\": .., \"l\": .., \"h\": ..} or {\"wlh\": [w, l, h]}"


def _number(path, value, field: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(path, f"expected a size in metres, got {value!r}", field)
    v = float(value)
    if not math.isfinite(v) or v <= 0.0:
        raise InputError(path, f"size must be finite and positive metres, got {value!r}", field)
    if v >= MAX_SIZE_M:
        raise InputError(path, f"size {v:g} m is not a vehicle's (must be below {MAX_SIZE_M:g} m)", field)
    return v


def _triple(path, value, field: str) -> tuple[float, float, float]:
    if isinstance(value, dict):
        sizes = []
        for short, long in NAMES:
            if short in value:
                sizes.append(_number(path, value[short], f"{field}.{short}" if field else short))
            elif long in value:
                sizes.append(_number(path, value[long], f"{field}.{long}" if field else long))
            else:
                raise InputError(path, f"missing {short!r} (expected {FORMS})", field or short)
        return tuple(sizes)
    if isinstance(value, (list, tuple)):
        where = field or "wlh"
        if len(value) != 3:
            raise InputError(path, f"expected three sizes [w, l, h], got {len(value)}", where)
        return tuple(_number(path, v, f"{where}[{k}]") for k, v in enumerate(value))
    raise InputError(path, f"expected {FORMS}, got {type(value).__name__}", field or "wlh")


def parse_wlh(data, path="wlh.json") -> tuple[float, float, float]:
    """(w, l, h) from a parsed ``wlh.json`` document (``path`` names it in errors)."""
    if isinstance(data, dict) and "wlh" in data:
        return _triple(path, data["wlh"], "wlh")
    return _triple(path, data, "")


def _load(path):
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except FileNotFoundError:
        raise InputError(path, "file not found") from None
    except OSError as exc:
        raise InputError(path, f"cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise InputError(path, "not UTF-8 text") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(path, f"not valid JSON: {exc.msg} (line {exc.lineno})") from None


def read_wlh(path: str | os.PathLike) -> tuple[float, float, float]:
    """Width, length and height in metres from a ``wlh.json`` file."""
    return parse_wlh(_load(path), path)


def read_wlh_info(path: str | os.PathLike) -> tuple[tuple[float, float, float], dict]:
    """(w, l, h) and the document's other keys (``{}`` for the bare list form)."""
    data = _load(path)
    wlh = parse_wlh(data, path)
    extra = {k: v for k, v in data.items() if k != "wlh"} if isinstance(data, dict) and "wlh" in data else {}
    return wlh, extra
