"""Local Hugging Face model folders (FLUX.1-dev's parts, its text encoders) loaded offline, a
broken one (truncated weights, a config that is not JSON, a file missing) said in one line naming
the folder instead of a transformers or diffusers traceback."""

from __future__ import annotations

import os

from ..errors import InputError


def load_pretrained(cls, folder: str | os.PathLike, what: str, **kwargs):
    """``cls.from_pretrained(folder, local_files_only=True, **kwargs)``; ``what`` names the part
    ("the T5 text encoder") in the error."""
    from safetensors import SafetensorError

    try:
        return cls.from_pretrained(str(folder), local_files_only=True, **kwargs)
    except (OSError, ValueError, KeyError, SafetensorError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(folder, f"cannot load {what}: {first}") from None
