"""The output folder of a run: every path in it is built here, and what runs wrote is recorded.

A scene package may come from someone else, so its strings (camera names, actor ids) are data:
they become path components only through :meth:`OutputTree.path`, which refuses anything that
would leave the output folder. Each path handed out is first recorded in a journal inside the
folder, so that a run later deletes exactly what runs here wrote, and a folder holding files
that no run wrote is recognised as somebody else's.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
from pathlib import Path, PurePosixPath

from ..errors import SymDriveError

JOURNAL = ".symdrive-written"  # one relative path a line; a trailing "/" claims a whole folder
LOCK = ".symdrive.lock"
STATE = "state.json"
REPORT = "report.json"
ASSET_CACHE = "asset_cache"  # mesh-only actors' sampled splats, shared by the stages that render them
# adapted restorers, each in a folder named by its own key (pipeline.stages.adapted_folder): they
# outlive a change of the run's key, which mostly changes how views are restored, not the drive
ADAPT_CACHE = "adapt"
KEYED_CACHES = frozenset({ADAPT_CACHE})
BOOKKEEPING = frozenset({JOURNAL, LOCK})
# A run's records: claimed like every output, and taken as a run's in a folder with a journal
# even where an older run wrote them unclaimed; in a folder without one they are somebody else's.
RUN_RECORDS = frozenset({STATE, REPORT})
# Temporaries of io.atomic: ".<stem>.<random>.part<ext>" (files), ".<name>.<random>.part" and
# ".<name>.old-<pid>" (folders); the random part is tempfile's.
_TEMP = re.compile(r"^\.(?P<base>.+)\.(?:[A-Za-z0-9_]+\.part(?P<ext>\.[^.]*)?|old-\d+)$")


class OutputError(SymDriveError):
    """The output folder cannot be used as asked (a path leaving it, files it does not own)."""


def output_folder(out: str | os.PathLike, option: str = "--out") -> Path:
    """``out`` as a command's output folder: one that is there or not yet; a file is refused."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OutputError(f"{out}: {option} names a file, not a folder")
    return out


def output_file(out: str | os.PathLike) -> Path:
    """``out`` as a command's output file: one that is there or not yet; a folder is refused."""
    out = Path(out)
    if out.is_dir():
        raise OutputError(f"{out}: --out names a folder, not a file")
    return out


class OutputTree:
    """Paths inside one output folder, each recorded as written by runs in this folder."""

    def __init__(self, root: str | os.PathLike):
        root = output_folder(root)
        self.root = root
        self.real_root = root.resolve()  # links on the way resolved once: every check compares to it
        self._claimed: set[str] | None = None

    # ---------------------------------------------------------------- paths

    def path(self, *parts: str | os.PathLike) -> Path:
        """``root/parts...`` for writing; refused (OutputError) if it would lie outside the root,
        or if a file no run here wrote is there (never written over, nor read as done)."""
        rel = _relative(self.root, parts)
        target = self.root.joinpath(*rel.parts)
        if not target.resolve().is_relative_to(self.real_root):  # a symlink inside pointing out
            raise OutputError(f"{self.root}: refusing to write outside the output folder: {rel}")
        if (target.exists() or target.is_symlink()) and not self.owns(rel.as_posix()):
            raise OutputError(f"{self.root}: {rel} is there and no symdrive run wrote it: refusing to write over it; "
                              "choose a new or empty --out")
        self._claim(rel.as_posix())
        return target

    def folder(self, *parts: str | os.PathLike) -> Path:
        """A folder handed whole to library code: everything under it counts as written here."""
        p = self.path(*parts)
        self._claim(_relative(self.root, parts).as_posix() + "/")
        return p

    def frame(self, kind: str, camera: str, frame: int, suffix: str = ".png", actor: str | None = None) -> Path:
        """``<kind>/<camera>[/<actor>]/<frame:06d><suffix>``, the layout of every per-frame output."""
        return self.path(kind, camera, *([actor] if actor else []), f"{frame:06d}{suffix}")

    # ---------------------------------------------------------------- what runs here wrote

    def claimed(self) -> set[str]:
        if self._claimed is None:
            try:
                lines = (self.root / JOURNAL).read_text(encoding="utf-8").splitlines()
            except FileNotFoundError:
                lines = []
            self._claimed = {ln for ln in lines if ln}
        return self._claimed

    def _claim(self, rel: str) -> None:
        claimed = self.claimed()
        if rel in claimed:
            return
        self.root.mkdir(parents=True, exist_ok=True)
        # O_APPEND writes of one short line are atomic, so render tasks in other processes can
        # claim paths in the same folder at once.
        with open(self.root / JOURNAL, "a", encoding="utf-8") as f:
            f.write(rel + "\n")
        claimed.add(rel)

    def owns(self, rel: str) -> bool:
        """Whether a file at ``rel`` (posix, relative to the root) was written by runs here."""
        claimed = self.claimed()
        p = PurePosixPath(rel)
        if rel in BOOKKEEPING or rel in claimed:
            return True
        if rel in RUN_RECORDS:
            return (self.root / JOURNAL).is_file()
        if any(str(a) + "/" in claimed for a in p.parents if str(a) != "."):
            return True
        m = _TEMP.match(p.name)  # a temporary of a claimed file or folder
        if m:
            stem = m.group("base") + (m.group("ext") or "")
            target = (p.parent / stem).as_posix().removeprefix("./")
            return target in BOOKKEEPING | RUN_RECORDS or target in claimed or target + "/" in claimed
        return False

    def foreign_files(self) -> list[str]:
        """Files (and links) in the folder that no run here wrote."""
        if not self.root.is_dir():
            return []
        out = []
        for dirpath, dirnames, filenames in os.walk(self.root):
            rel_dir = Path(dirpath).relative_to(self.root)
            for name in filenames + [d for d in dirnames if os.path.islink(os.path.join(dirpath, d))]:
                rel = (rel_dir / name).as_posix()
                if not self.owns(rel):
                    out.append(rel)
        return sorted(out)

    def remove_written(self) -> int:
        """Delete everything runs here wrote (claimed files and folders and their temporaries),
        and nothing else, except the keyed caches; returns how many entries went."""
        removed = 0
        kept = {c for c in self.claimed() if PurePosixPath(c).parts[0] in KEYED_CACHES}
        gone = self.claimed() - kept
        folders = {(self.root / c.rstrip("/")).parent for c in gone}
        for rel in sorted(gone, key=len, reverse=True):
            p = self.root / rel.rstrip("/")
            if not _inside(self.real_root, p):  # a journal line edited (or shipped) to point elsewhere
                continue
            if p.is_symlink() or p.is_file():
                p.unlink()
                removed += 1
            elif rel.endswith("/") and p.is_dir():
                shutil.rmtree(p)
                removed += 1
        removed += self.remove_temporaries()
        (self.root / JOURNAL).unlink(missing_ok=True)
        self._claimed = set()
        for rel in sorted(kept):
            self._claim(rel)
        for d in sorted(folders, key=lambda p: len(p.parts), reverse=True):
            while d != self.root and d.is_relative_to(self.root):
                try:
                    d.rmdir()  # only the emptied folders that held what was written go
                except OSError:
                    break
                d = d.parent
        return removed

    def remove_temporaries(self) -> int:
        """Delete the temporaries a killed run left beside (or inside) what runs here wrote."""
        claimed = self.claimed()
        parents = {(self.root / c.rstrip("/")).parent for c in claimed} | {self.root / c for c in claimed
                                                                           if c.endswith("/")}
        removed = 0
        for d in parents:
            if not d.is_dir() or d.is_symlink() or not _inside(self.real_root, d / "x"):
                continue
            for entry in d.iterdir():
                rel = entry.relative_to(self.root).as_posix()
                if _TEMP.match(entry.name) and self.owns(rel) and rel not in claimed:
                    shutil.rmtree(entry) if entry.is_dir() and not entry.is_symlink() else entry.unlink()
                    removed += 1
        return removed


def own_folder(out: str | os.PathLike, option: str = "--out") -> OutputTree:
    """``out`` for a command that writes its files by name (``restore``, ``insert``): new, empty
    or holding only what symdrive commands wrote there. A user's file there is refused before any
    work, since the command could write over it."""
    tree = OutputTree(output_folder(out, option))
    if foreign := tree.foreign_files():
        raise OutputError(f"{out}: holds {len(foreign)} file(s) no symdrive command wrote ({foreign[0]}"
                          f"{', ...' if len(foreign) > 1 else ''}): choose a new or empty {option}")
    return tree


@contextlib.contextmanager
def unmade_if_refused(root: Path):
    """Run the body; if it is refused (a :class:`SymDriveError`: bad input found before anything
    was written), the folders made for ``root`` on the way are removed again, where empty."""
    root = Path(root).absolute()
    top = next((p for p in [*reversed(root.parents), root] if not p.exists()), None)
    try:
        yield
    except SymDriveError:
        d = root
        while top is not None and d.is_relative_to(top):
            try:
                d.rmdir()
            except OSError:
                break
            d = d.parent
        raise


def _relative(root: Path, parts) -> PurePosixPath:
    rel = PurePosixPath(*[str(p) for p in parts])
    text = str(rel)
    if (rel.is_absolute() or "\\" in text or any(c in text for c in "\0\n\r")
            or any(p in ("..", ".") for p in rel.parts) or not rel.parts):
        raise OutputError(f"{root}: refusing to write outside the output folder: {text!r}")
    return rel



def _inside(real_root: Path, p: Path) -> bool:
    """Whether ``p`` itself lies in the folder: no ``..`` in it and its parent, links resolved,
    the root or below it (``p`` may be a link: removing it removes the link only)."""
    return ".." not in p.parts and p.parent.resolve().is_relative_to(real_root)
