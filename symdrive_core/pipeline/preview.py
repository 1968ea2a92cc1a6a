"""One camera's frames of a scene package, background and every posed actor: what ``symdrive
render`` writes (its options are in ``cli/pipeline.py``) and the Blender add-on's preview shows.

A quick look at a scene, not a run: no plan, no stages, no masks. Frames are written as
``render/<camera>/<frame:06d>.png`` inside ``--out``, every path built by :class:`OutputTree`
and every file written atomically. ``--width``/``--height`` render at another size than the
package's, the intrinsics scaled to match (aspect kept when only one is given)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from ..errors import InputError


def check_frames(frames: list[int], n_frames: int, where: str = "--frames") -> None:
    """Every index in ``frames`` is a frame of the package (0 to ``n_frames - 1``)."""
    bad = [f for f in frames if not 0 <= f < n_frames]
    if bad:
        raise InputError(where, f"frame {bad[0]} is not within 0:{n_frames - 1}")


def preview_size(width: int, height: int, out_width: int | None = None,
                 out_height: int | None = None) -> tuple[int, int]:
    """The output size: as given, or the missing side from the camera's aspect."""
    if out_width is None and out_height is None:
        return width, height
    if out_width is None:
        out_width = max(1, round(out_height * width / height))
    if out_height is None:
        out_height = max(1, round(out_width * height / width))
    if out_width < 1 or out_height < 1:
        raise InputError("--width/--height", f"size must be positive, got {out_width}x{out_height}")
    return int(out_width), int(out_height)


def scaled_camera(camera, width: int, height: int):
    """``camera`` seen at ``width`` x ``height``: K scaled per axis (pixel centres at +0.5, so
    scaling the continuous image coordinates is exact)."""
    import numpy as np

    if (width, height) == (camera.width, camera.height):
        return camera
    S = np.diag([width / camera.width, height / camera.height, 1.0])
    frames = [replace(f, K=S @ np.asarray(f.K, dtype=np.float64)) for f in camera.frames]
    return replace(camera, width=width, height=height, frames=frames)


def preview_manifest(manifest, camera: str, width: int | None = None, height: int | None = None):
    """The manifest with just ``camera``, scaled to the requested size."""
    try:
        cam = manifest.camera(camera)
    except KeyError:
        names = ", ".join(c.name for c in manifest.cameras) or "none"
        raise InputError(manifest.path or manifest.root, f"no camera named {camera!r} (cameras: {names})",
                         "cameras") from None
    w, h = preview_size(cam.width, cam.height, width, height)
    return replace(manifest, cameras=[scaled_camera(cam, w, h)])


def render_images(manifest, camera: str, frames: list[int], *, width: int | None = None,
                  height: int | None = None, device: str = "cpu"):
    """Yield ``(frame, rgb [H, W, 3] float)`` for ``frames`` of ``camera``: background splats and
    every actor posed in that frame."""
    from .scene_render import SceneRenderer

    m = preview_manifest(manifest, camera, width, height)
    renderer = SceneRenderer(m, device=device)
    for fi in frames:
        yield fi, renderer.render(camera, fi).rgb


def render_package(package, camera: str, frames: list[int] | None, out, *, width: int | None = None, height: int | None = None,
                   device: str = "cpu", allow_external: bool = False, progress: bool = False) -> list[Path]:
    """``symdrive render``: write ``frames`` (None: the first) as PNGs under ``out``; returns their paths."""
    from tqdm import tqdm

    from ..io.images import write_image
    from ..scene import check_files, load_manifest
    from .outputs import OutputTree

    manifest = load_manifest(package, allow_external=allow_external)
    m = preview_manifest(manifest, camera, width, height)  # the camera checked before any asset is read
    frame_list = [0] if frames is None else list(frames)
    check_frames(frame_list, len(m.cameras[0].frames))
    check_files(manifest)
    tree = OutputTree(Path(out))
    written = []
    images = render_images(manifest, camera, frame_list, width=width, height=height, device=device)
    for fi, rgb in tqdm(images, total=len(frame_list), desc="render", unit="frame", disable=not progress):
        written.append(write_image(tree.frame("render", camera, fi), rgb))
    return written
