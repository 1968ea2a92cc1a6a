"""``symdrive render``: one camera's frames as PNGs inside --out, resized with K scaled."""

from dataclasses import replace

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.errors import InputError
from symdrive_core.io.images import read_image
from symdrive_core.io.ply import write_splats
from symdrive_core.pipeline.preview import check_frames, render_images
from symdrive_core.scene import load_manifest
from tests.conftest import random_gaussians


def test_render_writes_the_frames_inside_out(make_package, tmp_path):
    path = make_package(n_frames=3)
    out = tmp_path / "out"
    assert main(["render", str(path), "--camera", "front", "--frames", "2,0:1", "--out", str(out), "--quiet"]) == 0
    pngs = sorted(p.relative_to(out).as_posix() for p in out.rglob("*.png"))
    assert pngs == ["render/front/000000.png", "render/front/000001.png", "render/front/000002.png"]
    assert all(p.resolve().is_relative_to(out.resolve()) for p in out.rglob("*"))
    img = read_image(out / pngs[0])
    assert img.shape == (24, 32, 3) and img.max() > 0


def test_resized_render_keeps_the_aspect_and_matches_a_downsampled_full_render(make_package, tmp_path):
    path = make_package(n_frames=1, width=64, height=48)
    g = random_gaussians(200, 0, 1, (10, 0, 1), 3.0)  # splats a few pixels wide: sub-pixel ones alias
    write_splats(path.parent / "background.ply", replace(g, log_scales=g.log_scales + 2.5))
    out = tmp_path / "out"
    assert main(["render", str(path), "--camera", "front", "--out", str(out), "--height", "24", "--quiet"]) == 0
    small = read_image(out / "render/front/000000.png")
    assert small.shape == (24, 32, 3)
    (_, full), = render_images(load_manifest(path), "front", [0])
    coarse = lambda img: img.reshape(4, img.shape[0] // 4, 4, img.shape[1] // 4, 3).mean(axis=(1, 3))  # noqa: E731
    # the same view, only the resolution changed: the coarse layout agrees, a mirrored one does not
    assert np.abs(coarse(small) - coarse(full)).mean() < 0.02
    assert np.abs(coarse(small) - coarse(full[:, ::-1])).mean() > 2 * np.abs(coarse(small) - coarse(full)).mean()


def test_bad_camera_or_frames_exit_2_and_write_nothing(make_package, tmp_path, capsys):
    path = make_package(n_frames=2)
    out = tmp_path / "out"
    assert main(["render", str(path), "--camera", "rear", "--out", str(out)]) == 2
    assert "no camera named 'rear'" in capsys.readouterr().err
    assert main(["render", str(path), "--camera", "front", "--frames", "0:5", "--out", str(out)]) == 2
    assert not out.exists()


def test_check_frames():
    check_frames([0, 4], 5)
    for bad in ([5], [0, 7]):
        with pytest.raises(InputError, match=f"frame {bad[-1]} is not within 0:4"):
            check_frames(bad, 5)
