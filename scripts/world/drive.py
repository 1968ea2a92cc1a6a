"""Camera poses along the street: the ego drive in the right lane, looking along the road."""

from __future__ import annotations

import numpy as np

from .street import LANE_WIDTH, Street

CAMERA_HEIGHT = 1.6
PITCH_DEG = 3.0  # looking slightly down, as a windscreen camera does
RIGHT_LANE = -LANE_WIDTH / 2  # lateral offset of the right lane's centre (right-hand traffic)


def camera_pose(street: Street, x: float, lateral: float = RIGHT_LANE, height: float = CAMERA_HEIGHT,
                pitch_deg: float = PITCH_DEG) -> np.ndarray:
    """OpenCV camera-to-world at the road point ``x`` (x right, y down, z forward)."""
    (px, py), yaw = street.frame_at(x, lateral)
    pitch = np.radians(pitch_deg)
    z = np.array([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), -np.sin(pitch)])
    x_axis = np.array([np.sin(yaw), -np.cos(yaw), 0.0])
    y_axis = np.cross(z, x_axis)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = x_axis, y_axis, z, (px, py, height)
    return c2w


def drive(street: Street, frames: int, spacing: float, start_x: float = 0.0, height: float = CAMERA_HEIGHT,
          pitch_deg: float = PITCH_DEG) -> list[np.ndarray]:
    return [camera_pose(street, start_x + i * spacing, height=height, pitch_deg=pitch_deg) for i in range(frames)]
