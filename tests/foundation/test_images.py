import os

import numpy as np
import pytest

from symdrive_core.errors import InputError
from symdrive_core.io.atomic import atomic_directory, atomic_path
from symdrive_core.io.images import read_id_map, read_image, read_mask, write_id_map, write_image, write_mask


@pytest.mark.parametrize("ext,tol", [("png", 0.5 / 255 + 1e-6), ("exr", 1e-3), ("tif", 0.0)])
def test_rgb_round_trip(tmp_path, ext, tol):
    img = np.random.default_rng(0).random((9, 13, 3)).astype(np.float32)
    write_image(tmp_path / f"a.{ext}", img, dtype="float" if ext == "tif" else None)
    back = read_image(tmp_path / f"a.{ext}")
    assert back.shape == (9, 13, 3) and back.dtype == np.float32
    assert np.abs(back - img).max() <= tol


def test_jpeg_reads_back_close(tmp_path):
    img = np.tile(np.linspace(0, 1, 16, dtype=np.float32)[None, :, None], (8, 1, 3))
    write_image(tmp_path / "a.jpg", img)
    assert np.abs(read_image(tmp_path / "a.jpg") - img).mean() < 0.02


def test_png_clips_and_exr_keeps_hdr(tmp_path):
    img = np.array([[[-1.0, 0.5, 7.0]]], dtype=np.float32)
    write_image(tmp_path / "c.png", img)
    np.testing.assert_allclose(read_image(tmp_path / "c.png")[0, 0], [0, 128 / 255, 1], atol=1e-6)
    write_image(tmp_path / "c.exr", img)
    np.testing.assert_allclose(read_image(tmp_path / "c.exr")[0, 0], img[0, 0], rtol=1e-3)


def test_masks_and_id_maps_exact(tmp_path):
    mask = (np.random.default_rng(1).random((6, 5)) > 0.5).astype(np.float32)
    write_mask(tmp_path / "m.png", mask)
    np.testing.assert_array_equal(read_mask(tmp_path / "m.png"), mask)
    ids = np.random.default_rng(2).integers(0, 60000, (6, 5))
    for ext in ("png", "exr"):
        write_id_map(tmp_path / f"i.{ext}", ids)
        np.testing.assert_array_equal(read_id_map(tmp_path / f"i.{ext}"), ids)
    with pytest.raises(ValueError, match="0..65535"):
        write_id_map(tmp_path / "bad.png", np.array([[70000]]))


def test_channels_option_and_missing_file(tmp_path):
    write_mask(tmp_path / "g.png", np.ones((2, 2)))
    assert read_image(tmp_path / "g.png", channels=3).shape == (2, 2, 3)
    with pytest.raises(InputError, match="nope.png: file not found"):
        read_image(tmp_path / "nope.png")



def test_grey_with_alpha_reads_as_grey_like_rgba(tmp_path):
    """A grey + alpha PNG (what some tools write for a monochrome camera) is a recorded image like
    an RGBA one: opaque pixels keep their grey, in all three channels."""
    grey = np.array([[0.2, 0.6], [1.0, 0.0]])
    write_image(tmp_path / "la.png", np.stack([grey, np.ones_like(grey)], -1))
    rgb = read_image(tmp_path / "la.png", channels=3)
    np.testing.assert_allclose(rgb, np.repeat(grey[:, :, None], 3, 2), atol=0.5 / 255)
    assert read_image(tmp_path / "la.png").shape == (2, 2, 2)

def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("killed")
    assert target.read_text() == "old" and os.listdir(tmp_path) == ["out.txt"]


def test_atomic_directory_replaces_whole(tmp_path):
    out = tmp_path / "pkg"
    out.mkdir()
    (out / "stale.txt").write_text("x")
    with atomic_directory(out) as tmp:
        (tmp / "new.txt").write_text("y")
    assert sorted(p.name for p in out.iterdir()) == ["new.txt"]
    assert [p.name for p in tmp_path.iterdir()] == ["pkg"]


def test_atomic_outputs_get_ordinary_permissions(tmp_path):
    import os
    import stat

    mask = os.umask(0o022)
    os.umask(mask)
    with atomic_path(tmp_path / "a.txt") as tmp:
        tmp.write_text("x")
    with atomic_directory(tmp_path / "d") as tmp:
        (tmp / "f").write_text("y")
    assert stat.S_IMODE((tmp_path / "a.txt").stat().st_mode) == 0o666 & ~mask
    assert stat.S_IMODE((tmp_path / "d").stat().st_mode) == 0o777 & ~mask
