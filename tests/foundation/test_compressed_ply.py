"""Compressed splat PLY (SuperSplat ``.compressed.ply``): written with plyfile, read by io.ply."""

import numpy as np
import pytest

from symdrive_core.errors import InputError
from symdrive_core.gaussians import SH_C0
from symdrive_core.io.ply import describe, read_splats
from tests.compressed_ply_files import BOX, pack_11_10_11, write_compressed_ply


def test_explicit_numbers(tmp_path):
    path = tmp_path / "one.compressed.ply"
    rotation = (3 << 30) | (1023 << 20) | (511 << 10) | 511  # largest is rot_3; rot_0 at the top of its range
    colour = (255 << 24) | (0 << 16) | (128 << 8) | 255
    write_compressed_ply(path, [BOX], [(pack_11_10_11(2047, 0, 1023), rotation, pack_11_10_11(0, 1023, 2047), colour)])
    g = read_splats(path)
    assert len(g) == 1 and g.sh_degree == 0
    np.testing.assert_allclose(g.means[0], [2.0, 0.0, 8 * 1023 / 2047], rtol=1e-6)
    np.testing.assert_allclose(g.log_scales[0], [-5.0, -1.0, -1.0], rtol=1e-6)
    np.testing.assert_allclose(g.quats[0], [0.70711, 0.0, 0.0, 0.70711], atol=2e-3)  # wxyz: 90 deg about z
    assert abs(np.linalg.norm(g.quats[0]) - 1) < 1e-6
    np.testing.assert_allclose(g.sh[0, 0], [0.5 / SH_C0, -0.5 / SH_C0, (128 / 255 - 0.5) / SH_C0], rtol=1e-5)
    # alpha 255 is kept finite: half an 8-bit step below 1, logit log(509)
    np.testing.assert_allclose(g.opacity_logits[0], np.log(509.0), rtol=1e-6)


def test_chunks_index_every_256_splats_and_old_files_without_colour_bounds(tmp_path):
    path = tmp_path / "two.compressed.ply"
    other = [10, 10, 10, 11, 11, 11, -3, -3, -3, -2, -2, -2]
    packed = [(pack_11_10_11(0, 0, 0), 0, 0, 0x80808080)] * 257
    write_compressed_ply(path, [BOX[:12], other], packed, colour_bounds=False)
    g = read_splats(path)
    np.testing.assert_allclose(g.means[255], [0, 0, 0])
    np.testing.assert_allclose(g.means[256], [10, 10, 10])
    np.testing.assert_allclose(g.log_scales[256], [-3, -3, -3])
    # colour stored directly in [0, 1]; alpha 0x80 = 128/255
    np.testing.assert_allclose(g.sh[0, 0], [(128 / 255 - 0.5) / SH_C0] * 3, rtol=1e-5)
    a = 128 / 255
    np.testing.assert_allclose(g.opacity_logits[0], np.log(a / (1 - a)), rtol=1e-5)
    # rotation word 0: largest is rot_0, the others at the bottom of their range
    small = -0.5 * np.sqrt(2)
    np.testing.assert_allclose(g.quats[0], [np.sqrt(max(0.0, 1 - 3 * small**2)), small, small, small], atol=1e-6)


def test_spherical_harmonics_element(tmp_path):
    path = tmp_path / "sh.compressed.ply"
    sh = np.zeros((1, 45), np.uint8)
    sh[0, 0], sh[0, 15], sh[0, 30], sh[0, 44] = 255, 128, 0, 1  # red's, green's and blue's first; blue's last
    write_compressed_ply(path, [BOX], [(0, 0, 0, 0)], sh=sh)
    g = read_splats(path)
    assert g.sh_degree == 3
    np.testing.assert_allclose(g.sh[0, 1], [4.0, (128.5 / 256 - 0.5) * 8, -4.0])  # channel-major, like f_rest
    np.testing.assert_allclose(g.sh[0, 15, 2], (1.5 / 256 - 0.5) * 8)
    assert describe(path, g)["sh_degree"] == 3


def test_too_few_chunks_and_bad_sh_are_named(tmp_path):
    path = tmp_path / "bad.compressed.ply"
    write_compressed_ply(path, [BOX], [(0, 0, 0, 0)] * 300)
    with pytest.raises(InputError, match="element chunk"):
        read_splats(path)
    write_compressed_ply(path, [BOX], [(0, 0, 0, 0)], sh=np.zeros((1, 10), np.uint8))
    with pytest.raises(InputError, match="element sh"):
        read_splats(path)


def test_round_trip_within_quantisation(tmp_path):
    """Encode random splats the way the format defines, decode, compare within one quantisation step."""
    rng = np.random.default_rng(0)
    n = 600
    means = rng.uniform(-50, 50, (n, 3))
    log_scales = rng.uniform(-6, 0, (n, 3))
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    rgb, alpha = rng.uniform(0, 1, (n, 3)), rng.uniform(0.05, 0.95, n)
    chunks, packed = [], []
    for c in range(0, n, 256):
        sl = slice(c, min(c + 256, n))
        lo, hi, slo, shi = means[sl].min(0), means[sl].max(0), log_scales[sl].min(0), log_scales[sl].max(0)
        chunks.append([*lo, *hi, *slo, *shi, 0, 0, 0, 1, 1, 1])
        for i in range(sl.start, sl.stop):
            p = np.round((means[i] - lo) / (hi - lo) * [2047, 1023, 2047]).astype(int)
            s = np.round((log_scales[i] - slo) / (shi - slo) * [2047, 1023, 2047]).astype(int)
            qi = q[i] * (1 if q[i][np.argmax(np.abs(q[i]))] >= 0 else -1)
            big = int(np.argmax(np.abs(qi)))
            rest = np.round((np.delete(qi, big) / np.sqrt(2) + 0.5) * 1023).astype(int)
            r = (big << 30) | (rest[0] << 20) | (rest[1] << 10) | rest[2]
            col = np.round(np.append(rgb[i], alpha[i]) * 255).astype(int)
            packed.append((pack_11_10_11(*p), r, pack_11_10_11(*s), (col[0] << 24) | (col[1] << 16) | (col[2] << 8) | col[3]))
    path = tmp_path / "rt.compressed.ply"
    write_compressed_ply(path, chunks, packed)
    g = read_splats(path)
    span = means.max(0) - means.min(0)
    assert np.all(np.abs(g.means - means) <= span / 1000)
    assert np.all(np.abs(g.log_scales - log_scales) <= 6 / 1000)
    dots = np.abs(np.sum(g.quats * q, axis=1))
    assert dots.min() > 0.999
    np.testing.assert_allclose(SH_C0 * g.sh[:, 0] + 0.5, rgb, atol=0.5 / 255 + 1e-6)
    np.testing.assert_allclose(1 / (1 + np.exp(-g.opacity_logits)), alpha, atol=0.5 / 255 + 1e-6)
