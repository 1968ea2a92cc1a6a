"""File formats: splat PLY (numpy only), images via OpenImageIO, atomic writes.

:func:`open_regular` opens a file for reading only if it is a regular file: a FIFO would block
the reader forever and a device such as ``/dev/zero`` never ends.
"""

from __future__ import annotations

import os
import shutil
import stat

from ..errors import InputError


def link_or_copy(src, dst) -> None:
    """Place ``src`` at ``dst`` as a hard link (no bytes copied, same file system), else a copy."""
    os.makedirs(os.path.dirname(os.fspath(dst)) or ".", exist_ok=True)
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def _describe_mode(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


LFS_POINTER = b"version https://git-lfs.github.com/spec/"  # how a Git LFS pointer file begins
LFS_POINTER_BYTES_MAX = 1024  # a pointer is three short lines


def check_regular(path, field: str | None = None) -> os.stat_result:
    """``os.stat(path)`` of a regular file (symlinks followed) that is not a Git LFS pointer, else
    :class:`InputError`."""
    try:
        st = os.stat(path)
    except (OSError, ValueError) as exc:
        raise InputError(path, "file not found" if isinstance(exc, FileNotFoundError)
                         else f"cannot open: {getattr(exc, 'strerror', None) or exc}", field) from None
    if not stat.S_ISREG(st.st_mode):
        raise InputError(path, f"is {_describe_mode(st.st_mode)}, not a regular file", field)
    if st.st_size <= LFS_POINTER_BYTES_MAX:
        with open_regular(path, field):  # checks the head
            pass
    return st


def open_regular(path, field: str | None = None):
    """``open(path, "rb")`` for a regular file only, checked on the opened descriptor (opening is
    non-blocking, so a FIFO put in the file's place cannot hang it)."""
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0)
    try:
        fd = os.open(path, flags)
    except (OSError, ValueError) as exc:
        raise InputError(path, "file not found" if isinstance(exc, FileNotFoundError)
                         else f"cannot open: {getattr(exc, 'strerror', None) or exc}", field) from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise InputError(path, f"is {_describe_mode(st.st_mode)}, not a regular file", field)
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        if st.st_size <= LFS_POINTER_BYTES_MAX:
            head = os.read(fd, len(LFS_POINTER))
            if head == LFS_POINTER:
                raise InputError(path, "is a Git LFS pointer, not the file's content (fetch it with `git lfs pull`)",
                                 field)
            os.lseek(fd, 0, os.SEEK_SET)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise
