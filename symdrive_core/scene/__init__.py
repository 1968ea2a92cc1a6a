"""Scene packages: manifest (versioned, validated), cameras, poses and trajectories. numpy only."""

from .manifest import (
    DEFAULT_SHADOW_RATIO,
    Actor,
    Camera,
    CameraFrame,
    Effects,
    Frame,
    IdMap,
    Manifest,
    ManifestError,
    MaskEntry,
    check_files,
    load_manifest,
    parse_manifest,
)
from .paths import EXTERNAL_HINT, NAME_MAX, check_name, check_relative, is_inside, resolve_inside
from .poses import Pose, interpolate_pose
from .visibility import box_corners_world, box_in_frustum, vehicle_local_box

__all__ = ["DEFAULT_SHADOW_RATIO", "EXTERNAL_HINT", "NAME_MAX", "check_name", "check_relative", "is_inside",
           "resolve_inside", "Actor", "Camera", "CameraFrame", "Effects", "Frame", "IdMap", "Manifest",
           "ManifestError", "MaskEntry", "Pose", "box_corners_world", "box_in_frustum", "check_files", "interpolate_pose", "load_manifest",
           "parse_manifest", "vehicle_local_box"]
