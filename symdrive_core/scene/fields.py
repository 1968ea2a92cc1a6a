"""Typed reads of a parsed JSON document, each refusal naming the file and the field (the
manifest's reader, and the readers of other JSON inputs). numpy only."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from .paths import check_name, check_path_text, check_relative


class FieldReader:
    """``fail`` raises ``error`` (an :class:`InputError` class) at ``path`` and the field's JSON path."""

    error: type[InputError] = InputError

    def __init__(self, path: Path):
        self.path = path

    def fail(self, where: str, message: str):
        raise self.error(self.path, message, where)

    def obj(self, v, where) -> dict:
        if not isinstance(v, dict):
            self.fail(where, f"expected an object, got {type(v).__name__}")
        return v

    def key(self, d: dict, k: str, where: str, default=...):
        if k not in d:
            if default is ...:
                self.fail(f"{where}.{k}" if where else k, "required field is missing")
            return default
        return d[k]

    def lst(self, v, where) -> list:
        if not isinstance(v, list):
            self.fail(where, f"expected a list, got {type(v).__name__}")
        return v

    def num(self, v, where, bound=None) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(where, f"expected a finite number, got {v!r}")
        try:
            x = float(v)
        except OverflowError:  # an integer too large for a float
            x = float("inf")
        if not np.isfinite(x):
            self.fail(where, f"expected a finite number, got {v!r}")
        if bound is not None and abs(x) > bound:
            self.fail(where, f"expected a number within +-{bound:g}, got {x:g}")
        return x

    def integer(self, v, where, minimum=None, maximum=None) -> int:
        if isinstance(v, bool) or not isinstance(v, int):
            self.fail(where, f"expected an integer, got {v!r}")
        if minimum is not None and v < minimum:
            self.fail(where, f"expected an integer >= {minimum}, got {v}")
        if maximum is not None and v > maximum:
            self.fail(where, f"expected an integer <= {maximum}, got {v}")
        return v

    def _checked(self, check, v, where):
        try:
            return check(v, where, self.path)
        except self.error:
            raise
        except InputError as exc:
            self.fail(where, exc.message)

    def name(self, v, where) -> str:
        return self._checked(check_name, v, where)

    def ref(self, v, where, allow_none=True) -> str | None:
        if v is None and allow_none:
            return None
        return self._checked(check_path_text, v, where)

    def output(self, v) -> str:
        return self._checked(check_relative, v, "output")

    def string(self, v, where, allow_none=False) -> str | None:
        if v is None and allow_none:
            return None
        if not isinstance(v, str) or not v:
            self.fail(where, f"expected a non-empty string, got {v!r}")
        return v

    def boolean(self, v, where) -> bool:
        if not isinstance(v, bool):
            self.fail(where, f"expected true or false, got {v!r}")
        return v

    def vector(self, v, n, where) -> np.ndarray:
        if (not isinstance(v, list) or len(v) != n
                or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in v)):
            self.fail(where, f"expected {n} numbers")
        try:
            a = np.asarray(v, dtype=np.float64)
        except OverflowError:  # an integer too large for a float
            self.fail(where, "expected finite numbers")
        if not np.all(np.isfinite(a)):
            self.fail(where, "expected finite numbers")
        return a

    def matrix(self, v, r, c, where) -> np.ndarray:
        if not isinstance(v, list) or len(v) != r:
            self.fail(where, f"expected a {r}x{c} matrix (list of {r} rows)")
        return np.stack([self.vector(row, c, f"{where}[{i}]") for i, row in enumerate(v)])
