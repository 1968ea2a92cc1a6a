import numpy as np
import pytest

from symdrive_core.errors import InputError
from symdrive_core.world.points import read_points, write_points


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
