"""One run per output folder: an exclusive lock held for the run's duration.

The lock is an advisory ``flock`` on a file in the output folder, so the operating system
releases it when its holder dies: a lock file left by a killed run is simply taken over. The
file names the holder (pid, host, start time) so that a refused second run can say who holds
it, and is removed when the run ends.
"""

from __future__ import annotations

import json
import os
import socket
import time
from pathlib import Path

from .outputs import LOCK, OutputError

try:
    import fcntl
except ImportError:  # Windows
    fcntl = None
    import msvcrt


class OutputLocked(OutputError):
    """Another run holds this output folder."""


class OutputLock:
    """``with OutputLock(out):`` holds ``out`` for one run; a second holder gets OutputLocked."""

    def __init__(self, out: str | os.PathLike):
        self.path = Path(out) / LOCK
        self._fd: int | None = None

    def __enter__(self) -> OutputLock:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        while True:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                _lock(fd)
            except OSError:
                holder = _describe(fd)
                os.close(fd)
                raise OutputLocked(f"{self.path.parent}: another run is writing here ({holder}); wait for it "
                                   f"to finish or choose another --out") from None
            if _same_file(fd, self.path):
                break
            os.close(fd)  # its holder removed the file as we took it: take the new one
        os.ftruncate(fd, 0)
        os.write(fd, json.dumps({"pid": os.getpid(), "host": socket.gethostname(),
                                 "since": time.strftime("%Y-%m-%dT%H:%M:%S")}).encode())
        self._fd = fd
        return self

    def __exit__(self, *exc) -> None:
        if self._fd is not None:
            self.path.unlink(missing_ok=True)  # removed while held, so no lock file outlives its run
            _unlock(self._fd)
            os.close(self._fd)
            self._fd = None


def _same_file(fd: int, path: Path) -> bool:
    try:
        return os.path.samestat(os.fstat(fd), os.stat(path))
    except FileNotFoundError:
        return False


def _lock(fd: int) -> None:
    if fcntl is not None:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    else:
        msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)


def _unlock(fd: int) -> None:
    if fcntl is not None:
        fcntl.flock(fd, fcntl.LOCK_UN)
    else:
        os.lseek(fd, 0, os.SEEK_SET)
        msvcrt.locking(fd, msvcrt.LK_UNLCK, 1)


def _describe(fd: int) -> str:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        info = json.loads(os.read(fd, 4096).decode() or "{}")
        return f"pid {info['pid']} on {info['host']}, since {info['since']}"
    except (OSError, ValueError, KeyError, TypeError):
        return "holder unknown"
