"""Errors that carry the file and the field they are about, for messages users can act on."""

from __future__ import annotations


class SymDriveError(Exception):
    """Base class: the command line turns these into a message and exit status 2."""


class InputError(SymDriveError):
    """Bad input file: names the file and, where known, the field."""

    def __init__(self, path, message: str, field: str | None = None):
        self.path = str(path)
        self.field = field
        where = f"{self.path}: {field}: " if field else f"{self.path}: "
        super().__init__(where + message)
