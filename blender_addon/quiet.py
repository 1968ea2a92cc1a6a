"""Keep Blender's render chatter out of the console and batch logs.

Cycles prints a status line per sample and per stage (``Fra:1 Mem:... | Sample 1/1``) on the
process's standard output from C code, where Python's ``sys.stdout`` cannot intercept it; Blender
5.x logs a line per saved image on standard error. :func:`quiet_output` points the process's
file descriptors 1 and 2 at a temporary file while a render runs and throws the text away on
success; if the render raises, the captured text is written to standard error before the
exception propagates, so nothing needed for a diagnosis is lost. Set ``SYMDRIVE_VERBOSE=1`` to
see everything.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import tempfile


def _flush_c_stdio() -> None:
    try:
        libc = ctypes.CDLL(None)
        libc.fflush(None)
    except (OSError, AttributeError, TypeError):  # no C runtime to reach (e.g. Windows): nothing buffered
        pass


def _flush_python() -> None:
    for stream in (sys.stdout, sys.stderr, sys.__stdout__, sys.__stderr__):
        with contextlib.suppress(Exception):
            stream.flush()


@contextlib.contextmanager
def quiet_output(enabled: bool | None = None):
    """Silence stdout and stderr at the file-descriptor level for the duration of the block."""
    if enabled is None:
        enabled = os.environ.get("SYMDRIVE_VERBOSE", "") in ("", "0")
    if not enabled:
        yield
        return
    try:
        saved = [os.dup(1), os.dup(2)]
    except OSError:  # no usable descriptors (embedded without a console): nothing to silence
        yield
        return
    sink = tempfile.TemporaryFile(mode="w+b")
    try:
        _flush_python()
        _flush_c_stdio()
        os.dup2(sink.fileno(), 1)
        os.dup2(sink.fileno(), 2)
        try:
            yield
        except BaseException:
            _restore(saved)
            sink.seek(0)
            text = sink.read().decode("utf-8", "replace").strip()
            if text:
                print(text[-20000:], file=sys.stderr, flush=True)
            raise
        _restore(saved)
    finally:
        for fd in saved:
            os.close(fd)
        sink.close()


def _restore(saved: list[int]) -> None:
    _flush_python()
    _flush_c_stdio()
    os.dup2(saved[0], 1)
    os.dup2(saved[1], 2)
