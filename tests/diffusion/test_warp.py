"""The geometry-guided warp on a synthetic textured ground seen by cameras along a path."""

import numpy as np
import pytest

from symdrive_core import conventions
from symdrive_core.diffusion.warp import (
    GroundModel,
    GroundWarper,
    SourceFrame,
    WarpConfig,
    WarpError,
    package_warper,
    pixel_rays,
)

HEIGHT_M = 10.0
W = H = 64
K = conventions.intrinsics(32.0, 32.0, W / 2, H / 2)
FLAT = GroundModel(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), np.zeros(1))


def texture(X: np.ndarray) -> np.ndarray:
    """Affine in the ground's (x, y): bilinear sampling of its straight-down images is exact."""
    x, y = X[:, 0], X[:, 1]
    return np.stack([0.1 + 0.01 * x + 0.02 * y, 0.5 - 0.01 * y, 0.3 + 0.005 * x + 0.003 * y], axis=1)


def down_camera(x: float) -> np.ndarray:
    """OpenCV camera over (x, 0) looking straight down, image right = -y, image up = +x."""
    c2w = np.eye(4)
    c2w[:3, :3] = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]).T
    c2w[:3, 3] = [x, 0.0, HEIGHT_M]
    return c2w


def render_ground(c2w, ground=FLAT) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The textured plane's image, its z-depth (0 where no ground) and its world points."""
    dirs = pixel_rays(K, c2w, W, H)
    lam, hits = ground.intersect(c2w[:3, 3], dirs)
    X = c2w[:3, 3] + lam[:, None] * dirs
    img = np.where(hits[:, None], texture(X), 0.0)
    return img.reshape(H, W, 3), np.where(hits, lam, 0.0).reshape(H, W), X


def path_warper(n=9, config=WarpConfig(), depth_edit=None) -> GroundWarper:
    sources = {}
    for i in range(n):
        c2w = down_camera(float(i))
        img, depth, X = render_ground(c2w)
        if depth_edit is not None:
            depth = depth_edit(depth, X)
        sources[i] = SourceFrame(K, c2w, img, depth, config.depth_tolerance)
    return GroundWarper(FLAT, sources, config)


def test_warp_reproduces_the_shifted_ground():
    warper = path_warper()
    c2w = conventions.lateral_shift(down_camera(4.0), 3.0)
    truth, _, _ = render_ground(c2w)
    w = warper.warp(4, K, c2w, W, H, np.zeros((H, W, 3)))
    assert w.mask.mean() > 0.7
    assert np.abs(w.image[w.mask] - truth[w.mask]).max() < 1e-9
    assert np.all(w.image[~w.mask] == 0)  # the raw render where no frame sees the ground


def test_a_frame_never_contributes_to_its_own_warp():
    warper = path_warper()
    warper.sources[4].image = np.full((H, W, 3), np.nan)
    c2w = conventions.lateral_shift(down_camera(4.0), 1.0)
    assert np.isfinite(warper.warp(4, K, c2w, W, H, np.zeros((H, W, 3))).image).all()
    alone = GroundWarper(FLAT, {4: path_warper().sources[4]}, WarpConfig())
    assert not alone.warp(4, K, c2w, W, H, np.zeros((H, W, 3))).mask.any()


def test_ground_hidden_in_every_recorded_depth_is_invalid():
    """A box standing on the ground around (4, -2): the recorded depth shows its top in front."""
    centre, half = np.array([4.0, -2.0]), 1.5

    def with_box(depth, X):
        inside = (np.abs(X[:, :2] - centre) < half).all(1).reshape(depth.shape)
        return np.where(inside, HEIGHT_M - 2.0, depth)

    warper = path_warper(depth_edit=with_box)
    c2w = conventions.lateral_shift(down_camera(4.0), 3.0)
    truth, _, X = render_ground(c2w)
    w = warper.warp(4, K, c2w, W, H, np.zeros((H, W, 3)))
    d = np.abs(X[:, :2] - centre).max(1).reshape(H, W)
    assert not w.mask[d < half].any()
    seen_without_box = path_warper().warp(4, K, c2w, W, H, np.zeros((H, W, 3))).mask
    away = d > half + 1.0  # beyond the box by more than a source pixel's footprint
    assert w.mask[away & seen_without_box].all()
    assert np.abs(w.image[w.mask] - truth[w.mask]).max() < 1e-9


def forward_camera(x: float, height: float = 1.6) -> np.ndarray:
    """OpenCV camera at (x, 0, height) looking along +x, level."""
    c2w = np.eye(4)
    c2w[:3, :3] = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]).T
    c2w[:3, 3] = [x, 0.0, height]
    return c2w


def test_pixels_above_the_horizon_or_beyond_range_are_invalid():
    cfg = WarpConfig(max_range_m=30.0)
    sources = {}
    for i in range(9):
        c2w = forward_camera(float(i))
        img, depth, _ = render_ground(c2w)
        sources[i] = SourceFrame(K, c2w, img, depth, cfg.depth_tolerance)
    warper = GroundWarper(FLAT, sources, cfg)
    c2w = conventions.lateral_shift(forward_camera(4.0), 2.0)
    w = warper.warp(4, K, c2w, W, H, np.zeros((H, W, 3)))
    assert not w.mask[: H // 2].any()  # level camera: the upper half looks at the sky
    X, ok = warper.ground_points(K, c2w, W, H)
    z = (X - c2w[:3, 3]) @ c2w[:3, 2]
    assert not ok[z > 30.0].any() and ok.reshape(H, W)[H // 2 + 4:].all()
    assert w.mask[H // 2 + 8:].mean() > 0.5


def test_ground_fit_recovers_a_tilted_plane():
    """Points on a 6 degree slope with 1 cm noise, clutter above it; cameras 1.6 m above it."""
    rng = np.random.default_rng(0)
    normal = np.array([-0.1, 0.02, 1.0]) / np.linalg.norm([-0.1, 0.02, 1.0])
    xy = rng.uniform([-5, -8], [25, 8], size=(20000, 2))
    z = (0.1 * xy[:, 0] - 0.02 * xy[:, 1]) + rng.normal(0, 0.01, len(xy))
    clutter = np.column_stack([rng.uniform(-5, 25, 4000), rng.uniform(-8, 8, 4000), rng.uniform(0.3, 6, 4000)])
    clutter[:, 2] += 0.1 * clutter[:, 0] - 0.02 * clutter[:, 1]
    points = np.vstack([np.column_stack([xy, z]), clutter])
    c2ws = []
    for i in range(20):
        c2w = forward_camera(float(i))
        c2w[2, 3] = 0.1 * i + 1.6 / normal[2]
        c2ws.append(c2w)
    model = GroundModel.fit(points, c2ws, WarpConfig(ground_window=4, ground_stride=5))
    assert len(model.normals) == 5  # anchors 0, 5, 10, 15 and the last camera
    assert np.all(model.normals @ normal > np.cos(np.deg2rad(0.5)))
    assert np.allclose(model.offsets, 0.0, atol=0.02)


def test_a_package_without_depth_or_background_is_refused(tmp_path):
    from symdrive_core.io.images import write_image
    from symdrive_core.io.points import write_points
    from symdrive_core.scene.manifest import Camera, CameraFrame, Frame, Manifest

    write_image(tmp_path / "0.png", np.zeros((H, W, 3), np.float32))
    c2w = forward_camera(0.0)
    cam = Camera("front", W, H, [CameraFrame(K, c2w, conventions.invert_rigid(c2w), "0.png")])
    m = Manifest("t", [Frame(0, 0.0)], [cam], [], root=tmp_path)
    with pytest.raises(WarpError, match="background.points or the background splats"):
        package_warper(m, cam)
    grid = np.stack(np.meshgrid(np.arange(10.0), np.arange(-3.0, 4.0), [0.0]), -1).reshape(-1, 3)
    write_points(tmp_path / "points.ply", grid, np.zeros_like(grid))
    m.background_points = "points.ply"
    with pytest.raises(WarpError, match="no depth"):
        package_warper(m, cam)



def pitched_camera(x: float) -> np.ndarray:
    """OpenCV camera 3 m over (x, 0) looking at the ground 6 m ahead (27 degrees down): steep
    enough that splat-rendered ground depth is within the warp's rendered-depth tolerance."""
    from tests.conftest import look_at_c2w

    return look_at_c2w((x, 0.0, 3.0), (x + 6.0, 0.0, 0.0))


def sparse_depth_package(root, zero: str, off_pixels=()):
    """Nine frames 3 m over the textured plane with LiDAR-like depth: 5% of the pixels
    measured (0 elsewhere); ``off_pixels`` (row, col) are measured 5% short of the ground, as a
    low object would be. Background points and flat splats lie on the plane."""
    from symdrive_core.gaussians import Gaussians
    from symdrive_core.io.images import write_image
    from symdrive_core.io.points import write_points
    from symdrive_core.scene.manifest import Camera, CameraFrame, Frame, Manifest

    rng = np.random.default_rng(0)
    frames, cam_frames = [], []
    for i in range(9):
        c2w = pitched_camera(float(i))
        img, depth, _ = render_ground(c2w)
        sparse = np.where(rng.random(depth.shape) < 0.05, depth, 0.0)
        for r, c in off_pixels:
            sparse[r, c] = 0.95 * depth[r, c]
        write_image(root / f"img/{i}.exr", img.astype(np.float32), dtype="float")
        write_image(root / f"depth/{i}.exr", sparse.astype(np.float32), dtype="float")
        frames.append(Frame(i, 0.1 * i))
        cam_frames.append(CameraFrame(K, c2w, conventions.invert_rigid(c2w), f"img/{i}.exr", f"depth/{i}.exr"))
    grid = np.stack(np.meshgrid(np.arange(-1.0, 30.0, 0.2), np.arange(-16.0, 16.0, 0.2), [0.0]), -1).reshape(-1, 3)
    write_points(root / "points.ply", grid[::7], np.zeros_like(grid[::7]))
    n = len(grid)
    splats = Gaussians.from_activated(grid, np.tile([1.0, 0, 0, 0], (n, 1)), np.tile([0.15, 0.15, 0.01], (n, 1)),
                                      np.full(n, 0.99), np.full((n, 3), 0.5))
    cam = Camera("front", W, H, cam_frames, zero)
    return Manifest("t", frames, [cam], [], background_points="points.ply", root=root), splats


NEAR_ROWS = slice(32, H)  # ground from 1.5 m to 6 m ahead


def test_sparse_depth_gaps_take_the_rendered_depth_not_sky(tmp_path):
    off = [(45, 20), (50, 40)]
    m, splats = sparse_depth_package(tmp_path, "unmeasured", off)
    cam = m.cameras[0]
    warper = package_warper(m, cam, splats)
    for src in warper.sources.values():
        near = src.ground[NEAR_ROWS].copy()
        for r, c in off:  # measured 5% short: the measured depth and its tight tolerance decide
            assert not src.ground[r, c]
            near[r - NEAR_ROWS.start, c] = True
        assert near.all()  # everywhere else the rendered depth fills the gaps
    c2w = conventions.lateral_shift(pitched_camera(4.0), 2.0)
    w = warper.warp(4, K, c2w, W, H, np.zeros((H, W, 3)))
    assert w.mask[NEAR_ROWS].all() and w.mask.mean() > 0.6  # farther up the render's depth bias exceeds its tolerance
    truth, _, _ = render_ground(c2w)
    assert np.abs(w.image[w.mask] - truth[w.mask]).max() < 1e-3  # bilinear sampling of perspective images

    m.cameras[0].depth_zero = "sky"  # the same maps read as dense: every gap is sky, never ground
    legacy = package_warper(m, cam, splats)
    assert max(src.ground.mean() for src in legacy.sources.values()) < 0.06  # the 5% measured
    assert legacy.warp(4, K, c2w, W, H, np.zeros((H, W, 3))).mask.mean() < 0.01


def test_sparse_depth_without_splats_uses_the_measured_pixels_only(tmp_path):
    m, _ = sparse_depth_package(tmp_path, "unmeasured")
    warper = package_warper(m, m.cameras[0])
    for src in warper.sources.values():
        stored = np.isfinite(src.depth) & (src.depth > 0)
        assert np.array_equal(src.ground, stored) and 0.02 < stored.mean() < 0.06


def road_points(x_from: float, x_to: float, z=lambda x: 0.0 * x) -> np.ndarray:
    """Road points every 0.5 m over x_from..x_to, 4 m either side of the path, at height z(x)."""
    xy = np.stack(np.meshgrid(np.arange(x_from, x_to, 0.5), np.arange(-4.0, 4.1, 0.5)), -1).reshape(-1, 2)
    return np.column_stack([xy, z(xy[:, 0])])


def test_windows_without_points_under_them_borrow_a_plane_and_say_which():
    """40 cameras 1 m apart; SfM found road only beyond x = 24 (the first windows have none)."""
    c2ws = [forward_camera(float(i)) for i in range(40)]
    model = GroundModel.fit(road_points(24.0, 50.0), c2ws)
    assert model.sources[:3] == ["nearest", "nearest", "neighbour"] and set(model.sources[4:]) == {"points"}
    assert np.allclose(model.normals, [0, 0, 1]) and np.allclose(model.offsets, 0.0, atol=1e-9)
    summary = model.summary()
    assert summary["planes"] == {"points": model.sources.count("points"), "neighbour": 2, "nearest": 2}
    first = summary["other_than_points"][0]
    assert first["cameras"] == [0, 8] and first["plane"] == "nearest" and "points under the camera path" in first["why"]

    # The package's own ground comes before a window farther than neighbour_windows away.
    tilted = (np.array([0.0, 0.0, 1.0]), -0.05)
    model = GroundModel.fit(road_points(24.0, 50.0), c2ws, package_ground=tilted)
    assert model.sources[:2] == ["package", "package"] and np.allclose(model.offsets[:2], -0.05)

    # The reconstruction's splat centres come first, where they cover the road.
    model = GroundModel.fit(road_points(24.0, 50.0), c2ws, splats=road_points(-5.0, 50.0, lambda x: 0.01 + 0 * x))
    assert model.sources[:3] == ["splats"] * 3 and np.allclose(model.offsets[:3], -0.01)


def test_no_ground_anywhere_is_one_line_naming_the_cameras():
    c2ws = [forward_camera(float(i)) for i in range(12)]
    with pytest.raises(WarpError, match="no ground under cameras 0 to 11: no ground plane: 0 points under"):
        GroundModel.fit(road_points(60.0, 70.0), c2ws)
    model = GroundModel.fit(road_points(60.0, 70.0), c2ws, package_ground=(np.array([0.0, 0.0, 1.0]), 0.0))
    assert set(model.sources) == {"package"}
