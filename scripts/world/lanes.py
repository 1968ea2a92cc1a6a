"""Exact lane-marking masks: the painted lines' coverage of each pixel, with occlusion.

A mask render makes every object that is not a lane marking a holdout and the film transparent,
so the alpha of the combined pass is, per pixel, the fraction of the pixel's area where the
camera sees paint (a car or tree in front of a line, and the sky, give 0). Lighting plays no
part, so a few unshaded samples with no bounces suffice. A pixel is lane when paint covers at
least half of it, which is what an image of the street shows as a line pixel.
"""

from __future__ import annotations

from contextlib import contextmanager

import bpy
import numpy as np

from . import render
from .street import MARKING

SAMPLES = 16  # jittered camera rays per pixel: coverage to 1/16
COVERED = 0.5  # a pixel is lane when at least this fraction of it shows paint


@contextmanager
def _markings_only():
    """Render only the lane markings' coverage (every other object a holdout); restore after."""
    scene = bpy.context.scene
    cyc = scene.cycles
    saved = {"samples": cyc.samples, "use_adaptive_sampling": cyc.use_adaptive_sampling,
             "use_denoising": cyc.use_denoising, "max_bounces": cyc.max_bounces}
    film = scene.render.film_transparent
    others = [o for o in scene.objects if o.type == "MESH" and not o.get(MARKING) and not o.is_holdout]
    cyc.samples, cyc.use_adaptive_sampling, cyc.use_denoising, cyc.max_bounces = SAMPLES, False, False, 0
    scene.render.film_transparent = True
    for o in others:
        o.is_holdout = True
    try:
        yield
    finally:
        for o in others:
            o.is_holdout = False
        scene.render.film_transparent = film
        for k, v in saved.items():
            setattr(cyc, k, v)


def lane_mask(cam_obj, c2w_opencv: np.ndarray) -> np.ndarray:
    """Boolean [H, W]: pixels of the OpenCV camera ``c2w_opencv`` that show lane paint."""
    with _markings_only():
        alpha = render.render(cam_obj, c2w_opencv)["alpha"]
    return alpha >= COVERED


def recorded_path(frame: int) -> str:
    return f"gt/lanes/recorded/{frame:06d}.png"


def lateral_path(offset_dir: str, frame: int) -> str:
    return f"gt/lanes/lateral/{offset_dir}/{frame:06d}.png"


def ground_truth_block(camera: str, recorded: dict[int, str], lateral: dict[float, dict[int, str]]) -> dict:
    """The manifest's ``ground_truth.lanes``: mask paths by frame, recorded views and lateral
    views (one entry per offset, as ``ground_truth.lateral``)."""
    def frames(d: dict[int, str]) -> dict[str, str]:
        return {str(i): d[i] for i in sorted(d)}

    return {"camera": camera, "definition": DEFINITION, "recorded": frames(recorded),
            "lateral": [{"offset_m": float(off), "camera": camera, "frames": frames(lateral[off])}
                        for off in sorted(lateral)]}


DEFINITION = (f"lane paint covers at least {COVERED:g} of the pixel (Cycles holdout render of the marking "
              f"objects, {SAMPLES} samples; occluders and sky give 0); 8-bit, 255 = lane")
