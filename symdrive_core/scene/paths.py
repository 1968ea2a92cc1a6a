"""Names that stay names and paths that stay inside their folder. numpy-free, stdlib only.

A scene package comes from someone else: its camera names, actor ids and scene name end up in
output file names, and its asset paths are opened for reading. :func:`check_name` accepts only
plain names (no separators, no ``..``, no control characters, no leading dot, bounded length);
:func:`check_relative` accepts only relative paths that stay inside their folder; and
:func:`resolve_inside` joins a path to a root and refuses the result unless it lies inside
the root (or another allowed folder) once symlinks are resolved.
"""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Callable

from ..errors import InputError

NAME_MAX = 128
# The same rule as the JSON Schema's pattern for names (manifest.schema.json). The first
# look-ahead refuses control characters anywhere: in Python's re (which jsonschema uses) ``$``
# also matches before a final newline.
NO_CONTROL = r"(?![\s\S]*[\x00-\x1f\x7f-\x9f])"
NAME_PATTERN = r"^" + NO_CONTROL + r"(?!\.)(?![\s\S]*\.\.)[^/\\]{1,128}$"
PATH_PATTERN = r"^" + NO_CONTROL + r"[\s\S]{1,4096}$"
OUTPUT_PATTERN = (r"^" + NO_CONTROL + r"(?![/\\])(?![A-Za-z]:)(?![\s\S]*(^|[/\\])\.\.([/\\]|$))"
                  r"(?!(\.[/\\]+)*\.?[/\\]*$)[\s\S]{1,4096}$")
_NAME_RE = re.compile(NAME_PATTERN)
_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")
PATH_MAX = 4096
EXTERNAL_HINT = ("pass --allow-external-assets to read files outside the package (a package exported "
                 "from Blender without --copy-assets names its assets where they are, outside it)")


def _fail(path, where: str | None, message: str):
    raise InputError(path if path is not None else (where or "name"), message,
                     where if path is not None else None)


def check_name(value, where: str, path=None) -> str:
    """``value`` if it is a plain name usable as one file-name component, else :class:`InputError`.

    ``where`` names the field (``cameras[0].name``); ``path`` the file it came from (the
    manifest), if any. A name is 1..128 characters with no ``/`` or ``\\``, no ``..``, no
    control characters (NUL included) and no leading dot.
    """
    if not isinstance(value, str) or not value:
        _fail(path, where, f"expected a non-empty name, got {value!r}")
    if len(value) > NAME_MAX:
        _fail(path, where, f"names are at most {NAME_MAX} characters, got {len(value)}")
    if _CONTROL.search(value):
        _fail(path, where, f"control characters (NUL included) are not allowed in a name: {value!r}")
    if "/" in value or "\\" in value:
        _fail(path, where, f"a name cannot contain '/' or '\\': {value!r}")
    if ".." in value:
        _fail(path, where, f"a name cannot contain '..': {value!r}")
    if value.startswith("."):
        _fail(path, where, f"a name cannot start with '.': {value!r}")
    if not _NAME_RE.match(value):  # the checks above are the pattern, spelt out
        _fail(path, where, f"not a valid name: {value!r}")
    return value


def check_path_text(value, where: str, path=None) -> str:
    """``value`` if it is a usable path string: non-empty, bounded, no control characters."""
    if not isinstance(value, str) or not value:
        _fail(path, where, f"expected a non-empty path, got {value!r}")
    if len(value) > PATH_MAX:
        _fail(path, where, f"paths are at most {PATH_MAX} characters, got {len(value)}")
    if _CONTROL.search(value):
        _fail(path, where, f"control characters (NUL included) are not allowed in a path: {value!r}")
    return value


def is_absolute_text(value: str) -> bool:
    """Absolute on any platform: ``/x``, ``\\x``, ``C:\\x``, ``C:x`` or ``\\\\server\\share``."""
    return (PurePosixPath(value).is_absolute() or PureWindowsPath(value).is_absolute()
            or bool(PureWindowsPath(value).drive) or value.startswith("\\"))


def escapes(value: str) -> bool:
    """Whether the relative path ``value`` climbs out of its folder with ``..`` (either separator)."""
    depth = 0
    for part in re.split(r"[/\\]+", value):
        if part in ("", "."):
            continue
        depth = depth - 1 if part == ".." else depth + 1
        if depth < 0:
            return True
    return False


def check_relative(value, where: str, path=None, *, allow_self: bool = False) -> str:
    """``value`` if it is a relative path inside its folder with no ``..`` (``a/b``, not ``/a``,
    ``C:a``, ``../a`` or ``a/../b``); ``allow_self``: ``.`` (the folder itself) is accepted too."""
    check_path_text(value, where, path)
    if is_absolute_text(value):
        _fail(path, where, f"must be a relative path inside the package, got {value!r}")
    if escapes(value) or ".." in re.split(r"[/\\]+", value):
        _fail(path, where, f"must stay inside the package (no '..'), got {value!r}")
    if not allow_self and all(p in ("", ".") for p in re.split(r"[/\\]+", value)):
        _fail(path, where, f"must name a folder inside the package, not the package itself: {value!r}")
    return value


def real(p) -> Path:
    """``p`` absolute with every symlink resolved (the parts that exist)."""
    return Path(os.path.realpath(p))


def is_inside(candidate, root) -> bool:
    """Whether ``candidate`` lies in ``root`` (or is it) once both have their symlinks resolved."""
    return real(candidate).is_relative_to(real(root))


def resolve_inside(root, rel: str, where: str | Callable[[], str], path=None, *,
                   allow_external: bool = False) -> Path:
    """``root / rel``, refused unless it lies inside ``root`` once symlinks are resolved (``allow_external`` lifts that). Anything that exists but is neither a
    regular file nor a folder (a FIFO, a device, a socket) is refused in every case: reading one
    can block forever or never end. ``where`` (the field, for messages) may be a function,
    called only when there is something to report."""
    def field() -> str:
        return where() if callable(where) else where

    if not isinstance(rel, str) or not rel or len(rel) > PATH_MAX or _CONTROL.search(rel):
        check_path_text(rel, field(), path)
    full = Path(root) / rel
    if not allow_external:
        if not is_inside(full, root):
            kind = ("an absolute path outside the package" if is_absolute_text(rel)
                    else "outside the package" if escapes(rel) else "a link that leads outside the package")
            _fail(path, field(), f"{rel!r} is {kind}; {EXTERNAL_HINT}")
    try:
        st = os.stat(full)
    except OSError:
        return full  # missing: the reader (or check_files) says so
    if not (stat.S_ISREG(st.st_mode) or stat.S_ISDIR(st.st_mode)):
        _fail(path, field(), f"{rel!r} is not a regular file (a FIFO, device or socket)")
    return full
