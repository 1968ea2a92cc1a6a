"""Episode videos: the first camera's view with a bird's-eye inset of the road, ego and traffic.

Encoded with imageio-ffmpeg (which ships its own ffmpeg binary; nothing is downloaded), H.264 in
MP4, written to a temporary file beside the target and renamed when complete.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.atomic import atomic_path
from .episode import ego_footprint

ROAD = np.array([70, 70, 70], np.uint8)
OFF = np.array([25, 60, 25], np.uint8)
ROUTE = np.array([230, 200, 40], np.uint8)
EGO = np.array([40, 200, 255], np.uint8)
ACTOR = np.array([230, 60, 50], np.uint8)
HIT = np.array([255, 0, 255], np.uint8)


def _fill(img: np.ndarray, poly: np.ndarray, colour: np.ndarray) -> None:
    """Fill a convex polygon [K, 2] given in pixel coordinates (x right, y down)."""
    h, w = img.shape[:2]
    x0, y0 = np.floor(poly.min(0)).astype(int)
    x1, y1 = np.ceil(poly.max(0)).astype(int)
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w - 1), min(y1, h - 1)
    if x1 < x0 or y1 < y0:
        return
    ys, xs = np.mgrid[y0:y1 + 1, x0:x1 + 1] + 0.5
    inside = np.ones(xs.shape, bool)
    sign = None
    for a, b in zip(poly, np.roll(poly, -1, axis=0)):
        cross = (b[0] - a[0]) * (ys - a[1]) - (b[1] - a[1]) * (xs - a[0])
        if sign is None:
            area = np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1])
            sign = 1.0 if area >= 0 else -1.0
        inside &= sign * cross >= 0
    img[y0:y1 + 1, x0:x1 + 1][inside] = colour


def birds_eye(env, record: dict, size: int, metres: float = 40.0) -> np.ndarray:
    """A ``size`` x ``size`` top view centred on the ego, ego heading up, ``metres`` across."""
    img = np.empty((size, size, 3), np.uint8)
    img[:] = OFF
    scale = size / metres
    cx, cy, yaw = record["x"], record["y"], record["yaw"]
    c, s = np.cos(yaw), np.sin(yaw)

    def px(xy):
        d = np.atleast_2d(xy) - [cx, cy]
        fwd = d @ [c, s]
        left = d @ [-s, c]
        return np.stack([size / 2 - left * scale, size * 0.65 - fwd * scale], axis=1)

    line, hw = env.area.line, env.area.half_width
    from ..scene.road import offset_polyline

    lo, hi = offset_polyline(line, -hw), offset_polyline(line, hw)
    for i in range(len(line) - 1):
        _fill(img, px(np.array([lo[i], lo[i + 1], hi[i + 1], hi[i]])), ROAD)
    route = env.route.xy
    for i in range(len(route) - 1):
        a, b = route[i], route[i + 1]
        d = (b - a) / max(np.linalg.norm(b - a), 1e-9) * 0.15
        n = np.array([-d[1], d[0]])
        _fill(img, px(np.array([a - n, b - n, b + n, a + n])), ROUTE)
    from ..traffic.overlap import footprints

    for a in record["actors"]:
        rect = footprints(np.array([[a["x"], a["y"]]]), np.array([a["yaw"]]), np.array([a["wlh"]]))[0]
        _fill(img, px(rect), ACTOR)
    ego = ego_footprint(cx, cy, yaw, env.wlh)
    _fill(img, px(ego), HIT if record.get("end") == "collision" else EGO)
    return img


def compose(image: np.ndarray | None, inset: np.ndarray) -> np.ndarray:
    """``inset`` in the top-right corner of ``image`` (or alone), even-sized for H.264."""
    if image is None:
        frame = inset.copy()
    else:
        frame = image.copy()
        s = inset.shape[0]
        frame[2:2 + s, -2 - s:-2] = inset
    h, w = frame.shape[:2]
    return np.pad(frame, ((0, h % 2), (0, w % 2), (0, 0)))


def write_video(frames: list[np.ndarray], path: str | Path, fps: float) -> Path:
    import imageio_ffmpeg

    path = Path(path)
    h, w = frames[0].shape[:2]
    with atomic_path(path) as tmp:
        writer = imageio_ffmpeg.write_frames(str(tmp), (w, h), fps=float(fps), codec="libx264",
                                             pix_fmt_out="yuv420p", macro_block_size=1,
                                             output_params=["-loglevel", "error"])
        writer.send(None)
        for f in frames:
            writer.send(np.ascontiguousarray(f, dtype=np.uint8))
        writer.close()
    return path
