import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from plyfile import PlyData, PlyElement

from symdrive_core.errors import InputError
from symdrive_core.io.ply import (
    REQUIRED,
    SURFEL_THICKNESS,
    describe,
    fold_3d_filter,
    read_splats,
    sh_rest_names,
    write_splats,
)
from tests.conftest import random_gaussians


def _assert_same(a, b):
    for name in ("means", "quats", "log_scales", "opacity_logits", "sh"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


@settings(max_examples=25, deadline=None)
@given(n=st.integers(0, 300), degree=st.integers(0, 3), seed=st.integers(0, 2**16))
def test_round_trip_any_degree_and_size(tmp_path_factory, n, degree, seed):
    g = random_gaussians(n, degree, seed)
    path = tmp_path_factory.mktemp("ply") / "s.ply"
    write_splats(path, g)
    h = read_splats(path)
    assert h.sh_degree == degree and len(h) == n
    _assert_same(g, h)


def _plyfile_write(path, n, degree, byte_order="<", text=False, drop=(), extra=()):
    rng = np.random.default_rng(0)
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", *sh_rest_names(degree),
             "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3", *extra]
    names = [nm for nm in names if nm not in drop]
    arr = np.empty(n, dtype=[(nm, "f4") for nm in names])
    for i, nm in enumerate(names):
        arr[nm] = rng.normal(size=n) if not nm.startswith("f_rest") else float(nm.split("_")[-1])
    el = PlyElement.describe(arr, "vertex")
    PlyData([el], text=text, byte_order=byte_order).write(str(path))
    return arr


def test_channel_major_f_rest_layout(tmp_path):
    # f_rest_i holds the value i: channel-major means red's 15 coefficients come first.
    _plyfile_write(tmp_path / "d3.ply", 4, 3)
    g = read_splats(tmp_path / "d3.ply")
    assert g.sh.shape == (4, 16, 3)
    np.testing.assert_array_equal(g.sh[0, 1:, 0], np.arange(0, 15))
    np.testing.assert_array_equal(g.sh[0, 1:, 1], np.arange(15, 30))
    np.testing.assert_array_equal(g.sh[0, 1:, 2], np.arange(30, 45))


@pytest.mark.parametrize("byte_order,text", [(">", False), ("<", True)])
def test_big_endian_and_ascii(tmp_path, byte_order, text):
    arr = _plyfile_write(tmp_path / "f.ply", 7, 1, byte_order=byte_order, text=text)
    g = read_splats(tmp_path / "f.ply")
    assert g.sh_degree == 1
    np.testing.assert_allclose(g.means[:, 0], arr["x"], rtol=1e-6)
    np.testing.assert_allclose(g.quats[:, 3], arr["rot_3"], rtol=1e-6)


def test_extra_properties_kept_normals_optional(tmp_path):
    _plyfile_write(tmp_path / "e.ply", 5, 0, drop=("nx", "ny", "nz"), extra=("semantic", "t_birth"))
    g = read_splats(tmp_path / "e.ply")
    assert g.normals is None and sorted(g.extra) == ["semantic", "t_birth"]
    write_splats(tmp_path / "back.ply", g)
    assert sorted(read_splats(tmp_path / "back.ply").extra) == ["semantic", "t_birth"]


def test_element_before_vertices_is_skipped(tmp_path):
    arr = _plyfile_write(tmp_path / "v.ply", 3, 0)
    cam = np.zeros(2, dtype=[("fx", "f8"), ("fy", "f8")])
    PlyData([PlyElement.describe(cam, "camera"), PlyElement.describe(arr, "vertex")]).write(str(tmp_path / "c.ply"))
    np.testing.assert_array_equal(read_splats(tmp_path / "c.ply").means[:, 2], arr["z"])


def test_missing_field_names_it(tmp_path):
    _plyfile_write(tmp_path / "m.ply", 3, 0, drop=("opacity",))
    with pytest.raises(InputError, match=r"m\.ply.*missing required property: no opacity"):
        read_splats(tmp_path / "m.ply")


def test_plain_point_cloud_is_not_a_splat_file(tmp_path):
    arr = np.zeros(3, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u1")])
    PlyData([PlyElement.describe(arr, "vertex")]).write(str(tmp_path / "pc.ply"))
    with pytest.raises(InputError, match="not a 3DGS splat file: no f_dc_0"):
        read_splats(tmp_path / "pc.ply")


def test_truncated_file(tmp_path):
    path = tmp_path / "t.ply"
    write_splats(path, random_gaussians(100, 2))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 500])
    with pytest.raises(InputError, match=r"truncated: header declares 100 vertices.*room for 9\d"):
        read_splats(path)


def test_ascii_row_count_mismatch(tmp_path):
    path = tmp_path / "a.ply"
    _plyfile_write(path, 4, 0, text=True)
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:-1]) + "\n")
    with pytest.raises(InputError, match="declares 4 vertices, file has 3 rows"):
        read_splats(path)


def test_nan_reported_and_droppable(tmp_path):
    g = random_gaussians(10, 0)
    g.means[2, 0] = np.nan
    g.opacity_logits[5] = np.inf
    write_splats(tmp_path / "n.ply", g)
    with pytest.raises(InputError, match="2 of 10 splats have NaN or Inf.*--drop-invalid"):
        read_splats(tmp_path / "n.ply")
    with pytest.warns(UserWarning, match="dropped 2 of 10 splats with NaN or Inf values"):
        assert len(read_splats(tmp_path / "n.ply", drop_invalid=True)) == 8


@pytest.mark.parametrize("content,message", [
    (b"not a ply", "not a PLY file"),
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 1\n", "no 'end_header'"),
    (b"ply\nformat weird 1.0\nend_header\n", "unsupported format"),
])
def test_bad_headers(tmp_path, content, message):
    (tmp_path / "b.ply").write_bytes(content)
    with pytest.raises(InputError, match=message):
        read_splats(tmp_path / "b.ply")


def test_bad_f_rest_count(tmp_path):
    _plyfile_write(tmp_path / "r.ply", 2, 1, drop=("f_rest_8",))
    with pytest.raises(InputError, match="f_rest"):
        read_splats(tmp_path / "r.ply")


def test_describe_and_required_fields(tmp_path):
    g = random_gaussians(20, 3)
    write_splats(tmp_path / "s.ply", g)
    info = describe(tmp_path / "s.ply")
    assert info["count"] == 20 and info["sh_degree"] == 3
    np.testing.assert_allclose(info["bounds_min"], g.means.min(0), rtol=1e-6)
    assert len(REQUIRED) == 14


def test_activated_views():
    g = random_gaussians(5, 0)
    np.testing.assert_allclose(g.scales, np.exp(g.log_scales), rtol=1e-6)
    np.testing.assert_allclose(g.opacities, 1 / (1 + np.exp(-g.opacity_logits)), rtol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(g.unit_quats, axis=1), 1.0, rtol=1e-6)
    g.quats[0] = 0.0
    np.testing.assert_array_equal(g.unit_quats[0], [1, 0, 0, 0])


def test_mip_splatting_3d_filter_is_folded_into_scales_and_opacity(tmp_path):
    arr = _plyfile_write(tmp_path / "mip.ply", 6, 1, extra=("filter_3D",))
    f = np.abs(arr["filter_3D"]).astype(np.float64)
    g = read_splats(tmp_path / "mip.ply")
    assert "filter_3D" not in g.extra  # folded, so a writer cannot apply it twice
    s = np.exp(np.stack([arr[f"scale_{i}"] for i in range(3)], 1).astype(np.float64))
    filtered = np.sqrt(s**2 + f[:, None] ** 2)  # Mip-Splatting: scales with the 3D filter
    np.testing.assert_allclose(g.scales, filtered, rtol=1e-5)
    alpha = 1 / (1 + np.exp(-arr["opacity"].astype(np.float64)))
    coef = np.sqrt(np.prod(s**2, 1) / np.prod(filtered**2, 1))  # its opacity compensation
    np.testing.assert_allclose(g.opacities, alpha * coef, rtol=1e-5)
    # the convolution keeps each Gaussian's integral: opacity * sqrt(det covariance)
    np.testing.assert_allclose(g.opacities * np.prod(g.scales, 1), alpha * np.prod(s, 1), rtol=1e-5)


def test_3d_filter_fold_stays_finite_in_hard_cases():
    log_scales = np.log(np.array([[1e-8, 1e-8, 1e-8], [1e4, 1e4, 1e4], [1.0, 1.0, 1e-30], [0.1, 0.2, 0.3]]))
    logits = np.array([40.0, -40.0, 60.0, 40.0])
    ls, lo = fold_3d_filter(log_scales.astype(np.float32), logits.astype(np.float32), np.array([0.01, 0.01, 0.5, 0.0]))
    assert np.isfinite(ls).all() and np.isfinite(lo).all()
    np.testing.assert_allclose(ls[0], np.log(0.01), rtol=1e-6)  # a tiny Gaussian becomes the filter
    np.testing.assert_allclose(ls[1], log_scales[1], rtol=1e-6)  # a huge one is unchanged
    np.testing.assert_allclose(lo[1], -40.0, rtol=1e-5)
    assert lo[0] < -30  # its opacity drops by (1e-8 / 0.01)^3
    np.testing.assert_array_equal(ls[3], log_scales[3].astype(np.float32))  # no filter: nothing changes
    assert lo[3] == np.float32(40.0)


def test_2dgs_surfels_read_as_flat_gaussians(tmp_path):
    arr = _plyfile_write(tmp_path / "surfels.ply", 5, 0, drop=("scale_2",))
    g = read_splats(tmp_path / "surfels.ply")
    np.testing.assert_allclose(g.log_scales[:, :2], np.stack([arr["scale_0"], arr["scale_1"]], 1))
    thinnest = np.minimum(arr["scale_0"], arr["scale_1"]) + np.log(SURFEL_THICKNESS)
    np.testing.assert_allclose(g.log_scales[:, 2], thinnest, rtol=1e-6)
    # one scale alone is still an error naming what is missing
    _plyfile_write(tmp_path / "one.ply", 5, 0, drop=("scale_1", "scale_2"))
    with pytest.raises(InputError, match="scale_1"):
        read_splats(tmp_path / "one.ply")
