"""The start points: of the training frames only, a drive's LiDAR returns joined by triangulated
points where no return is near."""

from __future__ import annotations

import numpy as np
import pytest

from symdrive_core.errors import InputError
from symdrive_core.importers import start_points as sp
from symdrive_core.importers.nerfstudio import read_nerfstudio
from symdrive_core.importers.start_points import StartPointsConfig, drop_heldout_returns, nearest_distance

from .demo_formats import demo_world, write_nerfstudio


def test_nearest_distance_is_the_float64_brute_force_far_from_the_origin():
    rng = np.random.default_rng(0)
    offset = np.array([4.5e5, -3.2e6, 120.0])  # UTM-sized coordinates
    ref = rng.uniform(-40, 40, (3000, 3)) + offset
    q = rng.uniform(-50, 50, (700, 3)) + offset
    oracle = np.sqrt(((q[:, None, :] - ref[None, :, :]) ** 2).sum(-1)).min(1)
    np.testing.assert_allclose(nearest_distance(q, ref, chunk=128), oracle, rtol=1e-12, atol=1e-9)
    assert np.isinf(nearest_distance(q, ref[:0])).all()  # no return at all: every point is beyond reach
    assert nearest_distance(q[:0], ref).shape == (0,)


def test_held_out_frames_returns_are_dropped_with_their_colours():
    src = type("S", (), {})()
    src.points = np.arange(18.0).reshape(6, 3)
    src.colors = np.arange(18.0).reshape(6, 3) / 18
    src.point_frames = np.array([0, 1, 2, 2, 3, 4])
    assert drop_heldout_returns(src, [0, 1, 3, 4]) == 2
    assert src.point_frames.tolist() == [0, 1, 3, 4]
    np.testing.assert_array_equal(src.points[:, 0], [0, 3, 12, 15])
    np.testing.assert_array_equal(src.colors * 18, src.points)


@pytest.fixture
def demo_drive(tmp_path):
    """The demo street as a nerfstudio drive whose "LiDAR" is the demo's points within 2 source
    units of the road under the cameras, each seen in a frame."""
    pytest.importorskip("pycolmap")
    world = demo_world(seed=6, max_splats=2000)
    src = read_nerfstudio(write_nerfstudio(world, tmp_path / "ns", with_points=False))
    path = world.c2w[:, :3, 3]
    d = np.min(np.linalg.norm(world.points[:, None] - path[None], axis=-1), axis=1)
    near = d < np.quantile(d, 0.5)
    src.points, src.colors = world.points[near], world.colors[near]
    src.point_frames = np.arange(int(near.sum())) % len(path)
    return src


def test_a_drives_returns_are_joined_by_the_triangulated_points_beyond_their_reach(demo_drive, tmp_path,
                                                                                   monkeypatch):
    seen = {}

    def spy(grouped, near, frames=None):
        seen["frames"] = frames
        seen["tri"] = triangulate(grouped, near, frames=frames)
        return seen["tri"]

    triangulate = sp.triangulate
    monkeypatch.setattr(sp, "triangulate", spy)
    returns = demo_drive.points[np.isin(demo_drive.point_frames, [f for f in range(30) if f % 5 != 2])]
    lines = []
    cfg = StartPointsConfig(beyond_lidar_m=0.3)
    sp.start_points(demo_drive, tmp_path / "out", 5, cfg, log=lines.append)
    assert seen["frames"] == [f for f in range(30) if f % 5 != 2]  # the held-out frames' images never
    tri = seen["tri"]
    assert tri.record["images"] == 24 and tri.record["points"] > 100
    far = np.sqrt(((tri.points[:, None] - returns[None]) ** 2).sum(-1)).min(1) > 0.3
    assert 0 < far.sum() < len(far)
    np.testing.assert_array_equal(demo_drive.points[:len(returns)], returns)
    np.testing.assert_array_equal(demo_drive.points[len(returns):], tri.points[far])
    assert (demo_drive.point_frames[len(returns):] == -1).all()
    assert demo_drive.notes["triangulated"]["joined"] == far.sum()
    assert any(f"{far.sum()} beyond the LiDAR's reach join its {len(returns)} returns" in line for line in lines)


def test_a_failed_triangulation_leaves_the_returns_alone_and_says_so(demo_drive, tmp_path, monkeypatch):
    def fails(grouped, near, frames=None):
        raise InputError("images", "cannot triangulate points from the images: no matches")

    monkeypatch.setattr(sp, "triangulate", fails)
    n = len(demo_drive.points)
    lines = []
    sp.start_points(demo_drive, tmp_path / "out", None, log=lines.append)
    assert len(demo_drive.points) == n and "triangulated" not in demo_drive.notes
    assert "the start is the LiDAR's returns alone" in lines[-1]


def test_returns_alone_when_asked(demo_drive, tmp_path, monkeypatch):
    monkeypatch.setattr(sp, "triangulate", lambda *a, **k: pytest.fail("triangulated"))
    n = len(demo_drive.points)
    sp.start_points(demo_drive, tmp_path / "out", None, StartPointsConfig(triangulate_beyond_lidar=False))
    assert len(demo_drive.points) == n


def test_the_ground_is_fitted_to_the_returns_alone(demo_drive, tmp_path, monkeypatch):
    """Joined points (of no frame, -1) start the reconstruction but the ground fit sees the
    returns only."""
    from symdrive_core.importers import package
    from symdrive_core.importers.package import Options, write_package

    seen = {}

    def spy(points, *args, **kwargs):
        seen["points"] = points
        raise RuntimeError("stop after the ground fit's input")

    n = len(demo_drive.points)
    demo_drive.points = np.concatenate([demo_drive.points, demo_drive.points[:5] + 30.0])
    demo_drive.colors = np.concatenate([demo_drive.colors, demo_drive.colors[:5]])
    demo_drive.point_frames = np.concatenate([demo_drive.point_frames, np.full(5, -1)])
    monkeypatch.setattr(package, "align", spy)
    with pytest.raises(RuntimeError, match="ground fit"):
        write_package(demo_drive, Options(out=tmp_path / "pkg"), progress=False)
    np.testing.assert_array_equal(seen["points"], demo_drive.points[:n])
