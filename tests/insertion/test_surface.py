import numpy as np
import pytest

from symdrive_core.insertion.surface import (
    sample_surface,
    surface_splats,
    surfel_spacing,
    triangle_areas,
)
from symdrive_core.rotations import quat_to_matrix, quats_z_to

# a unit square (two triangles, area 1) at z = 0 and a 2x1 rectangle at x = 5 (area 2)
VERTS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                  [5, 0, 0], [5, 2, 0], [5, 2, 1], [5, 0, 1]], float)
TRIS = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])


def test_samples_lie_on_the_mesh_and_follow_area():
    pts, normals, tri = sample_surface(VERTS, TRIS, 30000, np.random.default_rng(0))
    on_square = tri < 2
    assert np.allclose(pts[on_square, 2], 0) and np.all((pts[on_square, :2] >= 0) & (pts[on_square, :2] <= 1))
    assert np.allclose(pts[~on_square, 0], 5)
    assert np.allclose(np.linalg.norm(normals, axis=1), 1)
    assert np.allclose(np.abs(normals[on_square]), [0, 0, 1])
    # area 1 vs 2: a third of the samples on the square
    assert abs(on_square.mean() - 1 / 3) < 0.01
    # uniform inside the square: mean at its centre
    assert np.allclose(pts[on_square, :2].mean(0), 0.5, atol=0.01)


def test_weights_bias_the_sampling():
    _, _, tri = sample_surface(VERTS, TRIS, 20000, np.random.default_rng(1), weights=[1, 1, 0, 0])
    assert np.all(tri < 2)
    with pytest.raises(ValueError):
        sample_surface(VERTS, TRIS, 10, np.random.default_rng(1), weights=[0, 0, 0, 0])


def test_quats_rotate_z_onto_normals():
    rng = np.random.default_rng(2)
    n = rng.normal(size=(50, 3))
    n = np.concatenate([n / np.linalg.norm(n, axis=1, keepdims=True), [[0, 0, 1], [0, 0, -1]]])
    q = quats_z_to(n)
    for qi, ni in zip(q, n):
        assert np.allclose(quat_to_matrix(qi) @ [0, 0, 1], ni, atol=1e-9)


def test_surface_splats_are_flat_along_the_normal():
    pts, normals, _ = sample_surface(VERTS, TRIS, 100, np.random.default_rng(3))
    spacing = surfel_spacing(triangle_areas(VERTS, TRIS).sum(), 100)
    g = surface_splats(pts, normals, np.full((100, 3), 0.25), spacing, flatness=0.1)
    assert np.allclose(g.scales, [spacing, spacing, 0.1 * spacing], rtol=1e-5)
    assert np.allclose(g.base_colors, 0.25, atol=1e-6)
    R = np.stack([quat_to_matrix(q) for q in g.unit_quats])
    assert np.allclose(np.abs(np.einsum("nij,nj->ni", R, np.tile([0, 0, 1.0], (100, 1)))), np.abs(normals), atol=1e-5)
