"""One line on stderr when the CPU kernels compile, so a first frame's wait is not a silent one.

The kernels are compiled by numba once and kept in its on-disk cache (``cache=True``); a later
process loads them instead of compiling. numba reports a real compile (not a cache load) as a
``numba:compile`` event, which is what is listened to here.
"""

from __future__ import annotations

import os
import sys

from numba.core import config, event

PACKAGE = __name__.split(".")[0]


def cache_dir(dispatcher) -> str:
    """Where numba keeps the compiled ``dispatcher`` (NUMBA_CACHE_DIR, else beside its source)."""
    path = getattr(getattr(dispatcher, "_cache", None), "_cache_path", None)
    if path:
        return path
    if config.CACHE_DIR:
        return config.CACHE_DIR
    return os.path.join(os.path.dirname(dispatcher.py_func.__code__.co_filename), "__pycache__")


class CompileNotice(event.Listener):
    """Says once per process that this package's kernels are being compiled, and where they are cached."""

    def __init__(self, stream=None):
        self.stream = stream
        self.said = False

    def on_start(self, ev):
        dispatcher = ev.data.get("dispatcher")
        module = getattr(getattr(dispatcher, "py_func", None), "__module__", "") or ""
        if self.said or not module.startswith(PACKAGE + "."):
            return
        self.said = True
        print(f"{PACKAGE}: compiling the CPU kernels (once; cached in {cache_dir(dispatcher)})",
              file=self.stream or sys.stderr, flush=True)

    def on_end(self, ev):
        pass


_NOTICE: CompileNotice | None = None


def announce_compiles() -> None:
    """Register the notice (idempotent; the kernel modules call it when imported)."""
    global _NOTICE
    if _NOTICE is None:
        _NOTICE = CompileNotice()
        event.register("numba:compile", _NOTICE)
