"""Errors that carry the file and the field they are about, for messages users can act on."""

from __future__ import annotations

import re

_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")


def one_line(text: str) -> str:
    """``text`` with control characters (newlines, NUL, escapes) written as ``\\xNN``: a message
    naming a hostile file or field stays one line and cannot drive the terminal."""
    return _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", text)


class SymDriveError(Exception):
    """Base class: the command line turns these into a message and exit status 2."""


class InputError(SymDriveError):
    """Bad input file: names the file and, where known, the field (printed as one line)."""

    def __init__(self, path, message: str, field: str | None = None):
        self.path = str(path)
        self.field = field
        self.message = message  # without the file and field, for errors that wrap this one
        where = f"{self.path}: {field}: " if field else f"{self.path}: "
        super().__init__(one_line(where + message))
