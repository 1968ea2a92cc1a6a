"""The second camera of a rectified stereo rig as lateral ground truth of the first.

A rectified pair looks the same way with the same lens, one baseline apart along the first
camera's +x: exactly the lateral view the restoration stage must produce at that offset. So the
second camera's images are real pixels of the drive ``baseline`` metres to the side. The
importer takes that camera out of the package's cameras (it is never trained on) and writes its
images as ``ground_truth.lateral`` at the measured baseline, which ``restore --evaluate`` and
``run`` score like the demo street's Cycles truth.

The baseline is measured from the poses the source gives both cameras (for KITTI, from the
projection matrices); a pair that is not rectified (rotated, offset off the x axis, different
lens or image size) is refused naming the file and the field.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import conventions
from ..errors import InputError
from .frames import Grouped, View


@dataclass(frozen=True)
class RigTolerance:
    """How far a pair may be from an ideal rectified rig and still be taken as one."""

    rotation_deg: float = 0.5  # relative rotation of the two cameras
    off_axis: float = 0.05  # the baseline's y and z components, as a fraction of its length
    spread: float = 0.02  # frame-to-frame change of the baseline, as a fraction of it
    focal: float = 0.01  # relative difference of fx and of fy
    principal_px: float = 2.0  # difference of the principal points, pixels


@dataclass
class StereoTruth:
    """The second camera's views, frame by frame, and where it sits on the first's +x."""

    camera: str  # the package camera the truth is about
    name: str  # the second camera's name (its images' folder in the package)
    views: list[View]
    baseline: float  # source units along the first camera's +x (positive: to its right)


def relative_pose(first: View, second: View) -> np.ndarray:
    """The second camera in the first's camera frame (4x4)."""
    return conventions.invert_rigid(first.c2w) @ second.c2w


def check_pair(first: View, second: View, tol: RigTolerance) -> float:
    """The pair's baseline (source units along the first camera's +x), or InputError naming the
    second view's file and field where the pair is not rectified."""
    if (second.width, second.height) != (first.width, first.height):
        raise InputError(second.source, f"image is {second.width}x{second.height}, its rig partner "
                         f"({first.where}) is {first.width}x{first.height}", second.where)
    f1, f2 = np.diag(first.K)[:2], np.diag(second.K)[:2]
    if np.any(np.abs(f2 - f1) > tol.focal * f1):
        raise InputError(second.source, f"focal length {f2.tolist()} differs from its rig partner's "
                         f"{f1.tolist()} ({first.where}): not a rectified pair", second.where)
    c1, c2 = first.K[:2, 2], second.K[:2, 2]
    if np.any(np.abs(c2 - c1) > tol.principal_px):
        raise InputError(second.source, f"principal point {c2.tolist()} differs from its rig partner's "
                         f"{c1.tolist()} ({first.where}): not a rectified pair", second.where)
    rel = relative_pose(first, second)
    angle = np.degrees(np.arccos(np.clip((np.trace(rel[:3, :3]) - 1) / 2, -1.0, 1.0)))
    if angle > tol.rotation_deg:
        raise InputError(second.source, f"rotated {angle:.3g} degrees against its rig partner ({first.where}): "
                         "not a rectified pair", second.where)
    t = rel[:3, 3]
    if abs(t[0]) == 0 or np.linalg.norm(t[1:]) > tol.off_axis * abs(t[0]):
        raise InputError(second.source, f"offset {t.tolist()} from its rig partner ({first.where}) is not "
                         "along its x axis: not a rectified pair", second.where)
    return float(t[0])


def split_rig(grouped: Grouped, second: str, tol: RigTolerance = RigTolerance()) -> tuple[Grouped, StereoTruth]:
    """``grouped`` without camera ``second``, and that camera as lateral truth of the first
    remaining camera (the package's ground-truth camera)."""
    if second not in grouped.cameras:
        raise InputError("--lateral-truth", f"no camera {second!r} in the source (cameras: "
                         f"{', '.join(grouped.cameras)})")
    if len(grouped.cameras) < 2:
        raise InputError("--lateral-truth", f"the source has only camera {second!r}; a rig needs a second one")
    i = grouped.cameras.index(second)
    rest = Grouped([c for j, c in enumerate(grouped.cameras) if j != i], grouped.frame_keys,
                   [row for j, row in enumerate(grouped.table) if j != i], grouped.timestamps, grouped.left_out)
    first, views = rest.table[0], grouped.table[i]
    if any(v.image is None for v in views):
        raise InputError("--lateral-truth", "the lateral truth is the second camera's images: pass --images DIR")
    baselines = np.array([check_pair(a, b, tol) for a, b in zip(first, views)])
    baseline = float(np.median(baselines))
    worst = int(np.argmax(np.abs(baselines - baseline)))
    if abs(baselines[worst] - baseline) > tol.spread * abs(baseline):
        v = views[worst]
        raise InputError(v.source, f"baseline {baselines[worst]:.6g} differs from the rig's median {baseline:.6g} "
                         "(source units): the cameras are not one rig", v.where)
    return rest, StereoTruth(rest.cameras[0], second, views, baseline)


OFFSET_DECIMALS = 4  # the measured baseline in the manifest: to 0.1 mm


def lateral_entry(truth: StereoTruth, scale: float, place) -> dict:
    """The ``ground_truth.lateral`` entry of ``truth`` in a package whose world is ``scale``
    metres per source unit; ``place(image, copy_as)`` gives each image's path in the package."""
    offset = round(truth.baseline * scale, OFFSET_DECIMALS)
    frames = {str(fi): place(v.image, f"gt/lateral/{truth.name}/{fi:06d}{v.image.suffix.lower()}")
              for fi, v in enumerate(truth.views) if v.image is not None}
    return {"offset_m": offset, "camera": truth.camera, "frames": frames, "sensor": truth.name}
