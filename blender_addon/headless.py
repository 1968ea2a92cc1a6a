"""Headless export: ``blender --background scene.blend --python scripts/export_scene.py -- --out DIR``.

Reads the arguments after ``--``; exits with status 0 on success, 2 on a bad input (the message
names the file and field), 1 on anything else, so batch systems see failures.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import bpy


def parse_args(argv: list[str]) -> argparse.Namespace:
    args = argv[argv.index("--") + 1 :] if "--" in argv else []
    ap = argparse.ArgumentParser(prog="export_scene.py", description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, type=Path, help="package folder (replaced atomically)")
    ap.add_argument(
        "--frames", default=None, help="Blender frames a:b, inclusive (default: the scene's range)"
    )
    ap.add_argument("--scene", default=None, help="scene name (default: the active scene)")
    ap.add_argument("--no-masks", action="store_true", help="skip mask rendering")
    ap.add_argument("--copy-assets", action="store_true", help="copy splat/mesh assets into the package")
    return ap.parse_args(args)


def _frame_range(text: str | None) -> tuple[int | None, int | None]:
    if text is None:
        return None, None
    a, sep, b = text.partition(":")
    if not sep:  # a single frame
        b = a
    try:
        return (int(a) if a else None), (int(b) if b else None)
    except ValueError:
        raise SystemExit(f"export_scene.py: --frames: expected a:b with integers, got {text!r}") from None


def main(argv: list[str] | None = None) -> int:
    from . import export, register, unregister
    from .core import errors

    opts = parse_args(sys.argv if argv is None else argv)
    f0, f1 = _frame_range(opts.frames)
    scene = bpy.data.scenes.get(opts.scene) if opts.scene else bpy.context.scene
    if scene is None:
        print(f"export_scene.py: no scene named {opts.scene!r}", file=sys.stderr)
        return 2
    options = export.ExportOptions(
        out=opts.out,
        frame_start=f0,
        frame_end=f1,
        write_masks=not opts.no_masks,
        copy_assets=opts.copy_assets,
    )
    t0 = time.perf_counter()

    def progress(i: int, n: int) -> None:
        print(f"export_scene.py: frame {i}/{n}", flush=True)

    # The properties must be registered to read what the .blend stores; register only if the
    # add-on is not enabled, and undo it afterwards (Python's bpy module hangs at exit otherwise).
    registered_here = not hasattr(bpy.types.Scene, "symdrive")
    if registered_here:
        register()
    try:
        manifest = export.export_scene(scene, options, progress)
    except errors.SymDriveError as exc:
        print(f"export_scene.py: {exc}", file=sys.stderr)
        return 2
    finally:
        if registered_here:
            unregister()
    print(
        f"export_scene.py: wrote {manifest.path} ({len(manifest.frames)} frames, "
        f"{len(manifest.actors)} actors, {len(manifest.masks)} masks) in {time.perf_counter() - t0:.1f} s",
        flush=True,
    )
    return 0
