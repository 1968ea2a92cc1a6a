"""Readers for the ``ground_truth`` block that ``scripts/make_world.py`` writes.

    ground_truth = {
      "camera": "front",
      "train_frames": [0, 1, 3, ...], "heldout_frames": [2, 7, ...],
      "depth": "...",                       # how depth maps are stored
      "lateral": [{"offset_m": 0.5, "camera": "front",
                   "frames": {"0": "gt/lateral/+0.5/000000.png", ...},
                   "sensor": "front_right"}, ...],  # sensor: the rig camera that recorded them
      "insertion": [{"actor", "asset", "kind", "wlh", "pose": {"translation", "rotation"},
                     "camera", "frame", "with", "without", "mask", "shadow_mask" (or null),
                     "mask_pixels", "shadow_pixels"}, ...],
      "lanes": {"camera": "front", "definition": "...",   # exact lane-marking masks (lane IoU)
                "recorded": {"0": "gt/lanes/recorded/000000.png", ...},
                "lateral": [{"offset_m": 0.5, "camera": "front",
                             "frames": {"0": "gt/lanes/lateral/+0.5/000000.png", ...}}, ...]},
      "road": {"centerline": [[x, y, z], ...], "lanes": 2, "lane_width": 3.5},
      "vehicles": {"camera": "front",       # moving traffic (existing actors), exact visible masks
                   "frames": {"0": "gt/vehicles/000000.png", ...}},
      "edits": [{"kind": "remove" | "move" | "retime", "actor", "camera", "frame",
                 "image", "mask", "pose" (null for remove), "lateral_m" (move), "shift_s" (retime),
                 "mask_pixels"}, ...],
      "generator": {...}                    # settings and Cycles timings
    }

A lateral ground-truth camera is the frame's camera moved ``offset_m`` along its own +x
(``conventions.lateral_shift``; positive = right), same intrinsics and orientation.

An edit is a held-out frame rendered again with one existing actor removed, moved across the
road (``lateral_m``, positive = the ego's left) or put where it is ``shift_s`` later on its own
trajectory: the truth an edited scene's render of that frame is scored against.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .camera import CameraView, SeenBy
from .manifest import Manifest, ManifestError
from .poses import Pose


def split_frames(manifest: Manifest, holdout_every: int = 5) -> tuple[list[int], list[int]]:
    """(training frames, held-out frames): the package's own split, else every k-th frame
    (starting at k // 2) is held out."""
    gt = manifest.ground_truth or {}
    n = len(manifest.frames)
    if "train_frames" in gt:
        train = [int(i) for i in gt["train_frames"]]
        heldout = [int(i) for i in gt.get("heldout_frames", [])]
    else:
        heldout = list(range(holdout_every // 2, n, holdout_every)) if holdout_every > 0 and n > 1 else []
        train = [i for i in range(n) if i not in heldout]
    return train, heldout


def fitting_split(manifest: Manifest, holdout_every: int = 5) -> tuple[list[int], list[int]]:
    """:func:`split_frames` for a fit, which needs a frame to learn from (every frame held out
    is a fine split to score a given reconstruction, not to make one)."""
    train, heldout = split_frames(manifest, holdout_every)
    if not train:
        raise ManifestError(manifest.path or manifest.root, f"all {len(heldout)} frames are held out: no frame to "
                            "reconstruct from", "ground_truth.train_frames")
    return train, heldout


@dataclass
class LateralView(SeenBy):
    offset_m: float
    frame: int
    camera: CameraView  # the recorded frame's camera moved offset_m to its right
    image: str  # ground truth, relative to the package
    lanes: str | None = None  # its exact lane-marking mask, relative to the package
    sensor: str | None = None  # the rig camera that recorded it (None: rendered truth)


def lane_masks(manifest: Manifest) -> dict[tuple[str, float, int], str]:
    """(camera, offset_m, frame) -> lane mask path: offset 0.0 for the recorded views."""
    lanes = (manifest.ground_truth or {}).get("lanes", {})
    camera = lanes.get("camera", manifest.cameras[0].name)
    out = {(camera, 0.0, int(k)): rel for k, rel in lanes.get("recorded", {}).items()}
    for e in lanes.get("lateral", []):
        out.update({(e.get("camera", camera), float(e["offset_m"]), int(k)): rel for k, rel in e["frames"].items()})
    return out


def lateral_views(manifest: Manifest, camera: str | None = None) -> list[LateralView]:
    """Every lateral ground-truth image (``camera``: of that package camera only) with its
    (shifted) camera and lane mask (where the package has one), in offset then frame order."""
    masks = lane_masks(manifest)
    out = []
    for entry in (manifest.ground_truth or {}).get("lateral", []):
        cam = manifest.camera(entry.get("camera", manifest.cameras[0].name))
        if camera is not None and cam.name != camera:
            continue
        off = float(entry["offset_m"])
        for key, rel in sorted(entry["frames"].items(), key=lambda kv: int(kv[0])):
            out.append(LateralView(off, int(key), CameraView.of_frame(cam, int(key)).shifted(off), rel,
                                   masks.get((cam.name, off, int(key))), entry.get("sensor")))
    return out


@dataclass
class EditTruth:
    kind: str  # "remove" | "move" | "retime"
    actor: str  # the edited existing actor
    camera: str
    frame: int
    image: str  # the edited frame, relative to the package
    mask: str  # the actor's visible mask in it (remove: in the recorded frame)
    pose: Pose | None  # the actor's edited pose; None for remove
    lateral_m: float | None = None  # move: metres across the road, positive = the ego's left
    shift_s: float | None = None  # retime: seconds later on its own trajectory
    mask_pixels: int | None = None


def edit_truth(manifest: Manifest) -> list[EditTruth]:
    """Every edited held-out frame of the package, in the order written."""
    gt = manifest.ground_truth or {}
    camera = gt.get("camera", manifest.cameras[0].name)
    out = []
    for e in gt.get("edits", []):
        pose = e.get("pose")
        out.append(EditTruth(
            e["kind"], e["actor"], e.get("camera", camera), int(e["frame"]), e["image"], e["mask"],
            None if pose is None else Pose(np.array(pose["translation"], dtype=np.float64),
                                           np.array(pose["rotation"], dtype=np.float64)),
            None if e.get("lateral_m") is None else float(e["lateral_m"]),
            None if e.get("shift_s") is None else float(e["shift_s"]),
            None if e.get("mask_pixels") is None else int(e["mask_pixels"])))
    return out


def vehicle_masks(manifest: Manifest) -> dict[int, str]:
    """Frame -> mask of the moving traffic's visible pixels (empty for a package without traffic)."""
    frames = (manifest.ground_truth or {}).get("vehicles", {}).get("frames", {})
    return {int(k): rel for k, rel in sorted(frames.items(), key=lambda kv: int(kv[0]))}


def with_lateral_offsets(manifest: Manifest, offsets) -> Manifest:
    """A view of ``manifest`` whose lateral ground truth keeps only ``offsets`` (metres)."""
    from dataclasses import replace

    keep = {round(float(o), 6) for o in offsets}
    gt = manifest.ground_truth or {}
    lateral = [e for e in gt.get("lateral", []) if round(float(e["offset_m"]), 6) in keep]
    return replace(manifest, ground_truth={**gt, "lateral": lateral})


def scorable_lateral_truth(manifest: Manifest, offsets, frames: list[int] | None) -> tuple[Manifest | None, str]:
    """``manifest`` keeping only the lateral truth at ``offsets`` (metres) of ``frames`` (None:
    all), or None when none is left; and what goes unscored ("" when nothing). Restoring offsets
    no truth was recorded at is the normal case (a stereo rig's truth sits at its baseline): the
    caller restores them and scores the rest."""
    kept = with_lateral_offsets(manifest, offsets)
    views = [v for v in lateral_views(kept) if frames is None or v.frame in set(frames)]
    have = {round(v.offset_m, 6) for v in views}
    missing = [float(o) for o in offsets if round(float(o), 6) not in have]
    recorded = sorted({float(e["offset_m"]) for e in (manifest.ground_truth or {}).get("lateral", [])})
    why = "" if not missing else (
        f"no lateral truth at {', '.join(f'{o:+g}' for o in missing)} m for the frames restored (the package's "
        f"is at {', '.join(f'{o:+g}' for o in recorded)} m): restored, not scored")
    return (kept if views else None), why


def truth_camera(manifest: Manifest):
    """The package camera the ground truth is about (``ground_truth.camera``, else the first)."""
    name = (manifest.ground_truth or {}).get("camera")
    return manifest.camera(name) if name is not None else manifest.cameras[0]


def has_lateral_truth(manifest: Manifest) -> bool:
    return bool((manifest.ground_truth or {}).get("lateral"))


def has_insertion_truth(manifest: Manifest) -> bool:
    return bool((manifest.ground_truth or {}).get("insertion"))


def require_truth(manifest: Manifest, key: str, needed_by: str | None = None) -> None:
    """Stop a scorer before its work when the package lacks ``ground_truth.<key>``.

    Imported packages have no ground truth, which is normal input: the error is one line naming
    the manifest and the field, and ``needed_by`` (``"restore --evaluate needs it; ..."``) says
    which option asked for it and how to do without.
    """
    if not (manifest.ground_truth or {}).get(key):
        raise missing_truth(manifest, key, f"no {key} ground truth to score against", needed_by)


def missing_truth(manifest: Manifest, key: str | None, message: str, needed_by: str | None = None) -> ManifestError:
    """The error of a scorer that finds no ``ground_truth.<key>`` (no ``key``: none of the block)
    for what it was asked to score."""
    return ManifestError(manifest.path or manifest.root, message + (f" ({needed_by})" if needed_by else ""),
                         "ground_truth" + (f".{key}" if key else ""))


def with_placements(manifest: Manifest, count: int) -> Manifest:
    """A view of ``manifest`` whose held-out insertion placements keep only the first ``count``."""
    from dataclasses import replace

    gt = manifest.ground_truth or {}
    return replace(manifest, ground_truth={**gt, "insertion": gt.get("insertion", [])[:count]})
