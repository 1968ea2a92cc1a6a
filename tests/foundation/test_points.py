import numpy as np
import pytest

from symdrive_core.errors import InputError
from symdrive_core.io.points import read_points, write_points


def test_point_cloud_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    pts, cols = rng.normal(size=(100, 3)) * 50, rng.random((100, 3))
    write_points(tmp_path / "p.ply", pts, cols, normals=rng.normal(size=(100, 3)))
    p, c = read_points(tmp_path / "p.ply")
    assert np.allclose(p, pts, rtol=1e-6, atol=1e-4)
    assert np.abs(c - cols).max() <= 0.5 / 255 + 1e-6


def test_splat_file_is_not_a_point_cloud(tmp_path):
    path = tmp_path / "bad.ply"
    path.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nend_header\n" + bytes(4))
    with pytest.raises(InputError, match="lacks y, z, red"):
        read_points(path)


def test_ascii_point_cloud_reads_as_the_binary_one(tmp_path):
    """COLMAP's ``model_converter --output_type PLY`` and many tools write ASCII: the same reader."""
    rng = np.random.default_rng(1)
    pts, cols = rng.normal(size=(5, 3)), rng.integers(0, 256, size=(5, 3))
    head = "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n" \
           "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
    rows = "".join(f"{x:.6f} {y:.6f} {z:.6f} {r} {g} {b}\n" for (x, y, z), (r, g, b) in zip(pts, cols))
    (tmp_path / "a.ply").write_text(head + rows)
    p, c = read_points(tmp_path / "a.ply")
    assert np.allclose(p, pts, atol=1e-5) and np.allclose(c * 255, cols)


def test_truncated_point_cloud_is_refused(tmp_path):
    write_points(tmp_path / "p.ply", np.zeros((10, 3)), np.zeros((10, 3)))
    data = (tmp_path / "p.ply").read_bytes()
    (tmp_path / "p.ply").write_bytes(data[:-7])
    with pytest.raises(InputError, match="vertex"):
        read_points(tmp_path / "p.ply")
