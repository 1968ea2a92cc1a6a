"""safetensors files read whole, every way one can be broken (truncated, another kind, a folder)
said in one line naming the file, not as a library traceback."""

from __future__ import annotations

import os

from ..errors import InputError
from . import check_regular


def read_tensor_file(path: str | os.PathLike, kind: str, framework: str = "pt",
                     field: str | None = None) -> tuple[dict, dict]:
    """(tensors by name, metadata) of the safetensors file ``path``; ``kind`` says what it should
    be ("restorer weights") in the error, ``field`` the option that named it; ``framework`` is
    safetensors' ("pt" or "np")."""
    from safetensors import SafetensorError, safe_open

    check_regular(path, field)
    try:
        with safe_open(str(path), framework) as f:
            meta = dict(f.metadata() or {})
            tensors = {k: f.get_tensor(k) for k in f.keys()}  # noqa: SIM118 (not a dict)
    except (SafetensorError, OSError, ValueError) as exc:
        raise InputError(path, f"not readable as {kind}: {str(exc).splitlines()[0] if str(exc) else exc!r}",
                         field) from None
    return tensors, meta
