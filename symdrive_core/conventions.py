"""Frames, units and pixel conventions: the one place they are written down.

Everything else imports from here instead of re-deriving a flip or an offset inline.
numpy only: Blender's Python imports this module too.

* World: metres, right-handed, Z up (Blender's world).
* Camera: OpenCV (x right, y down, z forward). Manifests store both ``camera_to_world``
  and ``world_to_camera`` 4x4 matrices.
* Pixels: pixel (0, 0) covers [0, 1) x [0, 1); its centre is at (0.5, 0.5). A centred
  principal point is ``cx = W / 2``.
* Quaternions: scalar first, ``(w, x, y, z)``, as in INRIA 3DGS PLY files.
* Vehicles (3DRealCar frame): Z up, X along the length (forward), origin at the centre of the
  bounding box, so the underside is at ``z = -h / 2``; metric scale. ``wlh`` = (width, length,
  height) in metres, i.e. extents along local (Y, X, Z).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

UNITS = "metres"
WORLD_UP = np.array([0.0, 0.0, 1.0])
CAMERA_CONVENTION = "opencv"
QUATERNION_ORDER = "wxyz"
PIXEL_CENTER_OFFSET = 0.5
NEAR_PLANE = 0.01  # metres: what is closer to a camera than this is not drawn (nor checked for visibility)
FAR_PLANE = 1e10  # metres: nor what is farther than this

"""Add to an integer pixel index to get the coordinate of that pixel's centre."""

# Blender's camera looks down its local -Z with +Y up; OpenCV looks down +Z with +Y down.
# Going from one to the other flips the camera's local Y and Z axes (a diagonal matrix that is
# its own inverse).
BLENDER_TO_OPENCV_CAMERA = np.diag([1.0, -1.0, -1.0, 1.0])

# 3DRealCar frame: forward along +X, left along +Y, up along +Z.
VEHICLE_FORWARD = np.array([1.0, 0.0, 0.0])
VEHICLE_LEFT = np.array([0.0, 1.0, 0.0])
VEHICLE_UP = np.array([0.0, 0.0, 1.0])


MIN_SUN_ELEVATION_SIN = 1e-3  # a sun lower than this (sine of its elevation) grazes the ground: no ground shadow


def sun_above_horizon(sun_direction) -> np.ndarray | None:
    """The unit direction sunlight travels, or None when it travels upwards or grazes the ground
    (no ground shadow then). A zero or non-finite vector is an error."""
    s = np.asarray(sun_direction, dtype=np.float64)
    n = float(np.linalg.norm(s))
    if not np.isfinite(n) or n == 0.0:
        raise ValueError("sun_direction must be a finite non-zero vector")
    s = s / n
    return None if float(s @ WORLD_UP) > -MIN_SUN_ELEVATION_SIN else s


def blender_camera_to_opencv(c2w_blender: np.ndarray) -> np.ndarray:
    """Camera-to-world of a Blender camera object -> OpenCV camera-to-world (Y and Z flipped)."""
    c2w = np.array(c2w_blender, dtype=np.float64, copy=True)
    return c2w @ BLENDER_TO_OPENCV_CAMERA


def opencv_camera_to_blender(c2w_opencv: np.ndarray) -> np.ndarray:
    """Inverse of :func:`blender_camera_to_opencv` (the flip is its own inverse)."""
    c2w = np.array(c2w_opencv, dtype=np.float64, copy=True)
    return c2w @ BLENDER_TO_OPENCV_CAMERA


def is_rigid(M: np.ndarray) -> bool:
    """Whether a 4x4 matrix is a rotation (orthonormal, det +1) and a translation, last row 0 0 0 1."""
    R = M[:3, :3]
    return (np.allclose(R @ R.T, np.eye(3), atol=1e-4) and abs(np.linalg.det(R) - 1) < 1e-4
            and np.allclose(M[3], [0, 0, 0, 1]))


def invert_rigid(T: np.ndarray) -> np.ndarray:
    """Inverse of a 4x4 rigid transform, exact for rotation + translation."""
    T = np.asarray(T, dtype=np.float64)
    R, t = T[:3, :3], T[:3, 3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ t
    return out


def camera_center(c2w: np.ndarray) -> np.ndarray:
    return np.asarray(c2w, dtype=np.float64)[:3, 3].copy()


def lateral_shift(c2w_opencv: np.ndarray, offset_m: float) -> np.ndarray:
    """Move a camera sideways by ``offset_m`` metres along its own x axis (positive = right).

    This is how lateral novel views (C_d, C_-d) are made from a recorded camera C_0: same
    orientation, centre moved along the camera's right vector.
    """
    c2w = np.array(c2w_opencv, dtype=np.float64, copy=True)
    c2w[:3, 3] += float(offset_m) * c2w[:3, 0]
    return c2w


def both_sides(distances) -> list[float]:
    """Signed lateral offsets for unsigned distances: each distance ``d`` (metres) gives the views at
    ``-d`` and ``+d``, nearest first, left before right.

    The one rule behind every ``--offsets`` option: a command line names distances, a manifest's
    ``effects.lateral_offsets`` names signed offsets (positive = right, as :func:`lateral_shift`).
    """
    return sorted({s * abs(float(d)) for d in distances for s in (-1, 1) if d != 0}, key=lambda o: (abs(o), o))


def intrinsics(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], dtype=np.float64)


def intrinsics_from_fov(width: int, height: int, fov_x_rad: float) -> np.ndarray:
    """Pinhole K with square pixels and a centred principal point (cx = W/2, cy = H/2)."""
    fx = 0.5 * width / np.tan(0.5 * fov_x_rad)
    return intrinsics(fx, fx, width / 2.0, height / 2.0)


def blender_intrinsics(
    width: int,
    height: int,
    lens_mm: float,
    sensor_width_mm: float,
    sensor_height_mm: float,
    sensor_fit: str = "AUTO",
    shift_x: float = 0.0,
    shift_y: float = 0.0,
    pixel_aspect_x: float = 1.0,
    pixel_aspect_y: float = 1.0,
) -> np.ndarray:
    """OpenCV K of a Blender perspective camera, with sensor fit, pixel aspect and lens shift.

    Blender fits the sensor to the larger image side for ``AUTO`` (measured in aspect-corrected
    pixels), to the width for ``HORIZONTAL`` and to the height for ``VERTICAL``. Lens shift is a
    fraction of that fitted size; positive ``shift_x`` moves the view window right, so the optical
    axis lands left of the image centre (smaller u); positive ``shift_y`` moves it up, so the
    optical axis below the image centre (larger v in OpenCV's y-down pixels).
    """
    fit = sensor_fit.upper()
    aspect_w = width * pixel_aspect_x
    aspect_h = height * pixel_aspect_y
    if fit == "AUTO":
        fit = "HORIZONTAL" if aspect_w >= aspect_h else "VERTICAL"
        sensor_mm = sensor_width_mm
    elif fit == "HORIZONTAL":
        sensor_mm = sensor_width_mm
    elif fit == "VERTICAL":
        sensor_mm = sensor_height_mm
    else:
        raise ValueError(f"sensor_fit: expected AUTO, HORIZONTAL or VERTICAL, got {sensor_fit!r}")
    view_fac = aspect_w if fit == "HORIZONTAL" else aspect_h
    px_per_mm = view_fac / sensor_mm  # aspect-corrected pixels per mm on the sensor
    fx = lens_mm * px_per_mm / pixel_aspect_x
    fy = lens_mm * px_per_mm / pixel_aspect_y
    cx = width / 2.0 - shift_x * view_fac / pixel_aspect_x
    cy = height / 2.0 + shift_y * view_fac / pixel_aspect_y
    return intrinsics(fx, fy, cx, cy)


SENSOR_WIDTH_MM = 36.0  # Blender's default sensor, used where a camera is built from K


@dataclass(frozen=True)
class BlenderLens:
    lens_mm: float
    sensor_width_mm: float
    sensor_fit: str
    shift_x: float
    shift_y: float
    pixel_aspect_x: float
    pixel_aspect_y: float


def lens_from_intrinsics(K, width: int, height: int, sensor_width_mm: float = SENSOR_WIDTH_MM) -> BlenderLens:
    """Blender camera settings that give ``K`` (the inverse of :func:`blender_intrinsics`).

    Blender has one resolution per scene and pixel aspect values of at least 1, so unequal fx and
    fy become a pixel aspect and the sensor is fitted horizontally.
    """
    K = np.asarray(K, dtype=np.float64)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if fx <= 0 or fy <= 0:
        raise ValueError(f"focal lengths must be positive, got fx={fx}, fy={fy}")
    if abs(K[0, 1]) > 1e-9 * fx:
        raise ValueError(f"skewed intrinsics (K[0][1] = {K[0, 1]}) have no Blender equivalent")
    pax, pay = (1.0, fx / fy) if fx >= fy else (fy / fx, 1.0)
    view = width * pax  # horizontal sensor fit, in aspect-corrected pixels
    return BlenderLens(
        lens_mm=float(fx * sensor_width_mm / width),
        sensor_width_mm=float(sensor_width_mm),
        sensor_fit="HORIZONTAL",
        shift_x=float((width / 2.0 - cx) * pax / view),
        shift_y=float((cy - height / 2.0) * pay / view),
        pixel_aspect_x=float(pax),
        pixel_aspect_y=float(pay),
    )


def scale_intrinsics(K: np.ndarray, sx: float, sy: float | None = None) -> np.ndarray:
    """K for the same camera at an image ``sx`` (``sy``) times as wide (tall). Pixel edges sit at
    integers and centres at +0.5, so every continuous coordinate simply scales: cx' = sx * cx."""
    sy = sx if sy is None else sy
    return np.diag([float(sx), float(sy), 1.0]) @ np.asarray(K, dtype=np.float64)


def pixel_centers(width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """(u, v) coordinates of every pixel centre, each [H, W]."""
    u = np.arange(width, dtype=np.float64) + PIXEL_CENTER_OFFSET
    v = np.arange(height, dtype=np.float64) + PIXEL_CENTER_OFFSET
    return np.meshgrid(u, v)


def pixel_rays_camera(K: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Camera-frame rays [..., 3] through the centres of pixels (``xs``, ``ys``: integer column and
    row indices, any matching shape), scaled so z = 1 (the ray parameter is then the z-depth)."""
    pix = np.stack([np.asarray(xs, np.float64) + PIXEL_CENTER_OFFSET, np.asarray(ys, np.float64) + PIXEL_CENTER_OFFSET,
                    np.ones(np.shape(xs))], -1)
    return pix @ np.linalg.inv(np.asarray(K, dtype=np.float64)).T


def project_points(points_world: np.ndarray, w2c: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World points [N,3] -> (pixel coordinates [N,2], camera depth z [N]) in this convention."""
    p = np.asarray(points_world, dtype=np.float64)
    w2c = np.asarray(w2c, dtype=np.float64)
    pc = p @ w2c[:3, :3].T + w2c[:3, 3]
    z = pc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = (pc[:, :2] / z[:, None]) @ np.asarray(K, dtype=np.float64)[:2, :2].T + np.asarray(K)[:2, 2]
    return uv, z


def vehicle_ground_offset(wlh: np.ndarray | list[float]) -> float:
    """Height of a vehicle's origin above the ground it stands on (half its height)."""
    return 0.5 * float(wlh[2])


def vehicle_box_corners(wlh) -> np.ndarray:
    """The 8 corners [8,3] of a vehicle's bounding box in its local 3DRealCar frame."""
    w, l, h = (float(v) for v in wlh)
    sx, sy, sz = l / 2.0, w / 2.0, h / 2.0
    return np.array([[x, y, z] for x in (-sx, sx) for y in (-sy, sy) for z in (-sz, sz)])


# ---------------------------------------------------------------- colour
# 3DGS colours and images are sRGB-encoded; lighting, shading and Blender colour attributes are
# linear. The IEC 61966-2-1 curve, in float64.


def srgb_to_linear(x) -> np.ndarray:
    """sRGB-encoded values to linear light. Negative values clip to 0; values above 1 (splat
    colours can exceed it) follow the curve's power segment."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, None)
    return np.where(x <= 0.04045, x / 12.92, np.power((x + 0.055) / 1.055, 2.4))


def linear_to_srgb(x) -> np.ndarray:
    """Linear light in [0, 1] (clipped) to sRGB-encoded values."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def to_uint8(image: np.ndarray) -> np.ndarray:
    """[0, 1] floats to 8-bit, rounded to nearest (how training pairs and images are stored)."""
    return np.clip(np.rint(np.asarray(image, dtype=np.float32) * 255.0), 0, 255).astype(np.uint8)
