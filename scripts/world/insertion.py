"""Held-out insertion placements: a vehicle asset put into the street where the ego camera
sees it, rendered with its true lighting, plus its exact mask and the shadow it casts."""

from __future__ import annotations

import numpy as np
from mathutils import Matrix, Vector
from mathutils.bvhtree import BVHTree

from symdrive_core import conventions
from symdrive_core.rotations import quat_from_yaw
from symdrive_core.scene import Pose

from .street import LANE_WIDTH, PARK_OFFSET, Street

# (lateral offset from the centreline, metres ahead of the camera, facing backwards?)
SLOTS = [(-LANE_WIDTH / 2, 11.0, False),  # ahead in the ego lane
         (LANE_WIDTH / 2, 15.0, True),  # oncoming lane
         (-PARK_OFFSET, 8.0, False)]  # parked on the right


def placement_pose(street: Street, camera_x: float, slot: int, wlh) -> Pose:
    """3DRealCar pose: yaw along the road, origin half the car's height above the road."""
    lateral, ahead, backwards = SLOTS[slot % len(SLOTS)]
    (px, py), yaw = street.frame_at(camera_x + ahead, lateral)
    yaw += np.pi if backwards else 0.0
    return Pose(np.array([px, py, conventions.vehicle_ground_offset(wlh)]), quat_from_yaw(yaw))


def place_object(obj, pose: Pose) -> None:
    obj.matrix_world = Matrix(pose.matrix().tolist())


def shadow_mask(obj, c2w: np.ndarray, K: np.ndarray, depth: np.ndarray, object_mask: np.ndarray,
                sun_direction: np.ndarray) -> np.ndarray:
    """Pixels of the scene (not the car) whose surface point cannot see the sun past the car.

    Surface points come from the frame's z-depth; one ray per pixel towards the sun is tested
    against the car's own BVH, so the mask is the exact hard shadow of the car alone.
    """
    import bpy

    depsgraph = bpy.context.evaluated_depsgraph_get()
    bvh = BVHTree.FromObject(obj, depsgraph)  # object-local coordinates
    w2l = np.linalg.inv(np.array(obj.matrix_world))
    h, w = depth.shape
    u, v = conventions.pixel_centers(w, h)
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1)
    pts_cam = rays * depth[..., None]
    pts = pts_cam @ c2w[:3, :3].T + c2w[:3, 3]
    candidates = (depth > 0) & ~object_mask
    local_pts = pts @ w2l[:3, :3].T + w2l[:3, 3]
    to_sun = Vector((w2l[:3, :3] @ (-np.asarray(sun_direction, dtype=np.float64))).tolist()).normalized()
    out = np.zeros((h, w), bool)
    for y, x in zip(*np.nonzero(candidates)):
        hit, *_ = bvh.ray_cast(Vector(local_pts[y, x].tolist()), to_sun, 200.0)
        out[y, x] = hit is not None
    return out
