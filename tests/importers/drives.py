"""What the recorded-drive importer tests (KITTI raw, KITTI-360, nuScenes) share: rigid motions and
KITTI's calibration text, a known road with a wall on it as the LiDAR sees it, the depth a camera
should get from a scan, and the check that bad input exits 2 with one line and writes nothing.

Each test writes its dataset from known geometry; these pieces keep the expected values computed
one way, independently of the importers (no code of theirs is called here but the CLI)."""

from __future__ import annotations

import numpy as np

from symdrive_core.cli import main
from symdrive_core.conventions import invert_rigid
from symdrive_core.io.images import read_image
from symdrive_core.scene import load_manifest

MIN_DEPTH_M = 0.5  # LidarConfig's default: returns nearer to the camera are dropped
STEP_NS = 103_651_234  # KITTI's frame interval near 10 Hz, in nanoseconds


def rigid(R, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def moved(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``points`` [N, 3] moved by the rigid ``T`` [4, 4]."""
    return points @ T[:3, :3].T + T[:3, 3]


def numbers(values) -> str:
    """Numbers as KITTI's text files write them, space separated, to the last bit."""
    return " ".join(f"{float(v)!r}" for v in np.ravel(values))


def cam_to_cam(K: np.ndarray, width: int, height: int, rig: dict[int, tuple[float, np.ndarray]]) -> str:
    """KITTI raw's ``calib_cam_to_cam.txt`` (KITTI-360's ``perspective.txt`` is the same layout) of
    rectified cameras ``rig``: camera i -> (its ``t_x`` in ``P_rect_0i = K [I | (t_x, 0, 0)]``, its
    rectifying rotation), with the unrectified lines the importers do not read."""
    lines = ["calib_time: 09-Jan-2012 13:57:47", "corner_dist: 9.950000e-02"]
    for i, (tx, R_rect) in rig.items():
        P = K @ np.hstack([np.eye(3), [[tx], [0.0], [0.0]]])
        lines += [f"S_{i:02d}: 1.392000e+03 5.120000e+02", f"K_{i:02d}: {numbers(K)}", f"D_{i:02d}: 0 0 0 0 0",
                  f"R_{i:02d}: {numbers(np.eye(3))}", f"T_{i:02d}: 0 0 0", f"S_rect_{i:02d}: {width} {height}",
                  f"R_rect_{i:02d}: {numbers(R_rect)}", f"P_rect_{i:02d}: {numbers(P)}"]
    return "\n".join(lines) + "\n"


def timestamps(minute: str, second: int, first_ns: int, count: int) -> str:
    """A camera's ``timestamps.txt``: ``count`` frames ``STEP_NS`` apart from ``minute:second`` and
    ``first_ns`` nanoseconds, each to the nanosecond."""
    out = []
    for k in range(count):
        ns = first_ns + STEP_NS * k
        out.append(f"{minute}:{second + ns // 10**9:02d}.{ns % 10**9:09d}\n")
    return "".join(out)


# ---------------------------------------------------------------- the LiDAR's scene


WALL_POINTS = 112  # the last points of road_and_wall


def road_and_wall(ground_z: float) -> np.ndarray:
    """The road ahead of and beside a path along +x (at height ``ground_z``), and a wall 16 m ahead
    that hides part of it (its ``WALL_POINTS`` points last)."""
    x, y = np.meshgrid(np.arange(-2.0, 30.0, 0.45), np.arange(-8.0, 8.0, 0.55))
    road = np.stack([x.ravel(), y.ravel(), np.full(x.size, ground_z)], 1)
    wy, wz = np.meshgrid(np.arange(-4.0, 0.0, 0.3), np.arange(0.0, 2.0, 0.25))
    wall = np.stack([np.full(wy.size, 16.0), wy.ravel(), ground_z + wz.ravel()], 1)
    return np.concatenate([road, wall])


def write_velodyne(path, world: np.ndarray, world_from_velo: np.ndarray) -> None:
    """A Velodyne scan (KITTI's .bin: float32 x, y, z, reflectance) of the ``world`` points."""
    velo = moved(invert_rigid(world_from_velo), world)
    np.hstack([velo, np.full((len(velo), 1), 0.3)]).astype("<f4").tofile(path)


def landing(p: np.ndarray, K: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(column, row, seen) of the camera-frame points ``p`` [N, 3]: the pixel each lands in through
    the dataset's ``K`` (pixel centres at integers, so +0.5 to the package's) and whether it is
    ``MIN_DEPTH_M`` or more in front and inside the image."""
    with np.errstate(divide="ignore", invalid="ignore"):
        col = np.floor(K[0, 0] * p[:, 0] / p[:, 2] + K[0, 2] + 0.5)
        row = np.floor(K[1, 1] * p[:, 1] / p[:, 2] + K[1, 2] + 0.5)
    seen = (p[:, 2] >= MIN_DEPTH_M) & (col >= 0) & (col < width) & (row >= 0) & (row < height)
    return col, row, seen


def expected_depth(p: np.ndarray, K: np.ndarray, width: int, height: int) -> np.ndarray:
    """The sparse depth [H, W] of the camera-frame points ``p``: each pixel's nearest point, 0 where
    none lands; one point at a time, as a reader of the definition would."""
    p = p[p[:, 2] >= MIN_DEPTH_M]
    col, row, seen = landing(p, K, width, height)
    depth = np.zeros((height, width))
    for c, r, z in zip(col[seen].astype(int), row[seen].astype(int), p[seen, 2]):
        if depth[r, c] == 0 or z < depth[r, c]:
            depth[r, c] = z
    return depth


# ---------------------------------------------------------------- checks


def imported(argv: list[str], tmp_path_factory):
    """The package the import ``argv`` (without ``--out``) writes, images copied in, loaded."""
    out = tmp_path_factory.mktemp("pkg") / "pkg"
    assert main([*argv, "--out", str(out), "--copy-images", "--quiet"]) == 0
    return load_manifest(out)


def assert_cameras(package, c2w, K, tolerance_m: float) -> None:
    """Every frame of every camera of the imported ``package`` is where ``c2w(camera name, frame)``
    [4, 4] puts it in the source frame (to ``tolerance_m``), with the package K ``K(camera name)``
    exactly."""
    back = invert_rigid(np.asarray(package.source["transform"]))
    for cam in package.cameras:
        for fi, cf in enumerate(cam.frames):
            assert np.abs(back @ cf.camera_to_world - c2w(cam.name, fi)).max() < tolerance_m, (cam.name, fi)
            assert np.array_equal(cf.K, K(cam.name)), (cam.name, fi)


def assert_actor_poses(package, actor, box, tolerance_m: float) -> None:
    """The ``actor``'s pose at each frame of the imported ``package`` is ``box(frame)`` [4, 4] in
    the source frame (to ``tolerance_m``), and it has none where that is None."""
    back = invert_rigid(np.asarray(package.source["transform"]))
    assert len(actor.poses) == len(package.frames)
    for fi, pose in enumerate(actor.poses):
        want = box(fi)
        assert (pose is None) == (want is None), fi
        if pose is not None:
            assert np.abs(back @ pose.matrix() - want).max() < tolerance_m, fi


def assert_sparse_depth(package, want, rtol: float) -> None:
    """Every camera of the imported ``package`` has the depth maps ``want(camera name, frame)``
    gives: the same pixels measured, the same depths to ``rtol``, gaps declared unmeasured, and
    enough pixels measured (over 500) for that to say something."""
    measured = 0
    for cam in package.cameras:
        assert cam.depth_zero == "unmeasured"
        for fi, cf in enumerate(cam.frames):
            expected = want(cam.name, fi)
            got = read_image(package.resolve(cf.depth))[:, :, 0]
            assert np.array_equal(got > 0, expected > 0), (cam.name, fi)
            assert np.allclose(got, expected, rtol=rtol, atol=0), (cam.name, fi)
            measured += int((expected > 0).sum())
    assert measured > 500


def assert_metric_ground(package, road: np.ndarray, tolerance_m: float) -> None:
    """The LiDAR's ``road`` (source frame) is z = 0 of the package's metric world to within
    ``tolerance_m`` (what the fit's other term, the camera path's constant height, pulls it by),
    and the fit is not weak."""
    T = np.asarray(package.source["transform"])
    assert package.source["scale"] == 1.0
    assert np.abs(moved(T, road)[:, 2]).max() < tolerance_m
    assert package.source["ground_fit"]["weak"] == []


def refused(argv: list[str], tmp_path, capsys, *needles) -> None:
    """The import ``argv`` (without ``--out``) exits 2 with one line on stderr holding each of
    ``needles``, and writes nothing."""
    out = tmp_path / "out" / "pkg"
    rc = main([*argv, "--out", str(out), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert rc == 2, err
    assert len(err.splitlines()) == 1, err
    for n in needles:
        assert n in err, (n, err)
    assert not out.exists() and not (out.parent.exists() and any(out.parent.iterdir()))
