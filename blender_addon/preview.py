"""Splat preview: the active camera at the current frame, rendered by the backend.

The scene goes to the backend the way every export does: :func:`export.export_scene` writes a
temporary package of this one frame and the active camera (no masks, assets named where they
are), which the backend renders at the preview size (K scaled) with background splats and every
actor at its pose. The backend runs in Blender's Python when ``symdrive_core`` and its renderer
(torch, numba) import there, else as the ``symdrive render`` command named in the preferences.
The picture lands in the image datablock "SymDrive Preview".
"""

from __future__ import annotations

import contextlib
import importlib
import os
import shlex
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np

from . import core, export
from .core import errors

IMAGE_NAME = "SymDrive Preview"
PREF_PATH = "Edit > Preferences > Add-ons > SymDrive > symdrive command"
RENDERER_MODULES = ("torch", "numba", "symdrive_core.pipeline.scene_render", "symdrive_core.pipeline.preview")
COMMAND_TIMEOUT_S = 600


class PreviewError(errors.SymDriveError):
    """The preview cannot be made (no backend, no camera, the backend failed): one line to report."""


@dataclass
class Preview:
    image: bpy.types.Image
    rgb: np.ndarray  # [H, W, 3] as rendered
    backend: str  # "Blender's Python" or the command run
    export_s: float
    render_s: float


def in_process_available() -> bool:
    """Whether the backend's renderer imports in this Python (symdrive installed into Blender's)."""
    try:
        for name in RENDERER_MODULES:
            importlib.import_module(name)
    except ImportError:
        return False
    return True


def resolve_command(text: str) -> list[str] | None:
    """The argv prefix of the ``symdrive`` command the preference names: an executable file, a
    name on PATH, or a command line whose first word is one; None when there is none."""
    text = (text or "").strip()
    if not text:
        return None
    path = bpy.path.abspath(text)
    if os.path.isfile(path) and os.access(path, os.X_OK):
        return [path]
    found = shutil.which(text)
    if found:
        return [found]
    try:
        parts = shlex.split(text, posix=os.name != "nt")
    except ValueError:
        return None
    if len(parts) > 1:
        first = shutil.which(parts[0])
        if first:
            return [first, *parts[1:]]
    return None


def choose_backend(mode: str, command: str) -> list[str] | None:
    """None for in-process, else the command's argv prefix; PreviewError saying what to set when
    neither is there."""
    if mode in ("AUTO", "BLENDER") and in_process_available():
        return None
    if mode == "BLENDER":
        raise PreviewError(
            "SymDrive preview: symdrive_core's renderer (torch, numba) does not import in Blender's Python; "
            "install symdrive into it, or set the preview backend to Automatic and point "
            f"{PREF_PATH} at the symdrive executable"
        )
    argv = resolve_command(command)
    if argv is None:
        tried = "" if mode == "COMMAND" else "symdrive_core's renderer does not import in Blender's Python and "
        raise PreviewError(
            f"SymDrive preview: no backend: {tried}the symdrive command {command.strip()!r} was not found; "
            f"set {PREF_PATH} to the symdrive executable (for example <venv>/bin/symdrive)"
        )
    return argv


def preview_size(scene, lines: int) -> tuple[int, int]:
    """``lines`` high, the width keeping the scene's render aspect."""
    width, height = export.render_size(scene)
    return max(1, round(lines * width / height)), int(lines)


@contextlib.contextmanager
def _only_camera_exported(scene, camera):
    """Export flags set so that the package holds ``camera`` alone; restored afterwards."""
    saved = {ob.name: ob.symdrive.export for ob in scene.objects if ob.type == "CAMERA"}
    try:
        for ob in scene.objects:
            if ob.type == "CAMERA":
                ob.symdrive.export = ob == camera
        yield
    finally:
        for ob in scene.objects:
            if ob.name in saved:
                ob.symdrive.export = saved[ob.name]


def export_frame(scene, camera, folder: Path) -> Path:
    """A package of the current frame seen by ``camera`` (no masks, assets not copied); its manifest."""
    frame = scene.frame_current
    options = export.ExportOptions(
        out=folder / "package", frame_start=frame, frame_end=frame, write_masks=False, copy_assets=False,
        name="preview",
    )
    with _only_camera_exported(scene, camera):
        manifest = export.export_scene(scene, options)
    return Path(manifest.root) / "manifest.json"


def render_in_process(package: Path, camera: str, width: int, height: int) -> np.ndarray:
    from symdrive_core.pipeline.preview import render_images
    from symdrive_core.scene import load_manifest

    manifest = load_manifest(package, allow_external=True)  # the user's own files, named by the export
    (_, rgb), = render_images(manifest, camera, [0], width=width, height=height)
    return rgb


def render_with_command(argv: list[str], package: Path, camera: str, width: int, height: int,
                        folder: Path) -> np.ndarray:
    out = folder / "render"
    cmd = [*argv, "render", str(package), "--camera", camera, "--frames", "0", "--out", str(out),
           "--width", str(width), "--height", str(height), "--allow-external-assets", "--quiet"]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=COMMAND_TIMEOUT_S)
    except OSError as exc:
        raise PreviewError(f"SymDrive preview: cannot run {argv[0]!r} ({exc}); check {PREF_PATH}") from None
    except subprocess.TimeoutExpired:
        raise PreviewError(f"SymDrive preview: {argv[0]} render took over {COMMAND_TIMEOUT_S} s") from None
    if proc.returncode != 0:
        lines = [ln for ln in (proc.stderr or "").splitlines() if ln.strip()]
        why = lines[-1] if lines else f"exit status {proc.returncode}"
        raise PreviewError(f"SymDrive preview: {argv[0]} render failed: {why}")
    written = [ln.strip() for ln in proc.stdout.splitlines() if ln.strip().endswith(".png")]
    if not written:
        raise PreviewError(f"SymDrive preview: {argv[0]} render wrote no image (is it the symdrive command?)")
    path = Path(written[-1])
    if not path.resolve().is_relative_to(out.resolve()):
        raise PreviewError(f"SymDrive preview: {argv[0]} render reported {path}, outside {out}")
    return core.images().read_image(path, channels=3)


def to_image(rgb: np.ndarray, name: str = IMAGE_NAME) -> bpy.types.Image:
    """Put ``rgb`` (display values, top row first) into the image datablock ``name``, made or reused."""
    height, width = rgb.shape[:2]
    image = bpy.data.images.get(name)
    if image is not None and image.source != "GENERATED":
        image.name = f"{name} (old)"  # a file-backed image of that name: left alone
        image = None
    if image is None:
        image = bpy.data.images.new(name, width, height, alpha=True)
    elif tuple(image.size) != (width, height):
        image.scale(width, height)
    rgba = np.ones((height, width, 4), dtype=np.float32)
    rgba[..., :3] = np.clip(np.nan_to_num(rgb[..., :3]), 0.0, 1.0)
    image.pixels.foreach_set(rgba[::-1].ravel())  # Blender stores the bottom row first
    image.update()
    return image


def show_in_image_editor(context, image) -> bool:
    """Show ``image`` in an Image Editor: one already open, else Blender's render view (its
    preference decides where); False without a UI or where none could be found."""
    wm = context.window_manager
    if bpy.app.background or wm is None or not wm.windows:
        return False

    def _set():
        for window in wm.windows:
            for area in window.screen.areas:
                if area.type == "IMAGE_EDITOR":
                    area.spaces.active.image = image
                    return True
        return False

    if _set():
        return True
    with contextlib.suppress(RuntimeError):
        bpy.ops.render.view_show("INVOKE_DEFAULT")
    return _set()


def render_preview(context, lines: int, mode: str, command: str) -> Preview:
    """Export the current frame, render it through the chosen backend, fill the preview image."""
    scene = context.scene
    camera = scene.camera
    if camera is None or camera.type != "CAMERA":
        raise PreviewError(f"{scene.name}: no active camera to preview (set the scene's camera)")
    argv = choose_backend(mode, command)  # before any work: a missing backend is reported at once
    width, height = preview_size(scene, lines)
    with tempfile.TemporaryDirectory(prefix="symdrive-preview-") as tmp:
        t0 = time.perf_counter()
        package = export_frame(scene, camera, Path(tmp))
        t1 = time.perf_counter()
        if argv is None:
            rgb = render_in_process(package, camera.name, width, height)
        else:
            rgb = render_with_command(argv, package, camera.name, width, height, Path(tmp))
        t2 = time.perf_counter()
    backend = "Blender's Python" if argv is None else Path(argv[0]).name
    return Preview(to_image(rgb), rgb, backend, t1 - t0, t2 - t1)
