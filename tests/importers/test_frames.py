"""Rigs and frames: several cameras on shared frames, order by name or timestamp, held-out split."""

from __future__ import annotations

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.importers.frames import natural_key, split_heldout
from symdrive_core.scene import load_manifest

from .demo_formats import CAMERA_HEIGHT, World, demo_world, link_images, write_colmap

pytest.importorskip("pycolmap")


def test_split_like_the_demo():
    train, held = split_heldout(30, 5)
    assert held == [2, 7, 12, 17, 22, 27] and len(train) == 24
    assert split_heldout(4, None) == ([0, 1, 2, 3], [])


def test_natural_order():
    assert sorted(["img10.png", "img9.png", "img100.png"], key=natural_key) == ["img9.png", "img10.png", "img100.png"]


def test_rig_folders_become_cameras_on_shared_frames(tmp_path, capsys):
    w = demo_world(seed=5, max_splats=2000)
    turn = np.diag([-1.0, 1.0, -1.0, 1.0])  # the rear camera: the front one turned about its y axis
    n = len(w.names)
    names = [f"front/{i:04d}.png" for i in range(n)] + [f"rear/{i:04d}.png" for i in range(n)]
    rig = World(S=w.S, names=names, images=w.images + w.images, K=w.K, width=w.width, height=w.height,
                c2w=np.concatenate([w.c2w, w.c2w @ turn]), c2w_demo=w.c2w_demo, splats=w.splats,
                points=w.points, colors=w.colors)
    model = write_colmap(rig, tmp_path / "sparse")
    link_images(rig, tmp_path / "images")
    out = tmp_path / "pkg"
    rc = main(["import", "colmap", str(model), "--images", str(tmp_path / "images"), "--out", str(out),
               "--camera-height", str(CAMERA_HEIGHT), "--copy-images"])
    assert rc == 0, capsys.readouterr().err
    m = load_manifest(out)  # images copied inside: no external assets
    assert [c.name for c in m.cameras] == ["front", "rear"] and len(m.frames) == n
    f, r = m.cameras[0].frames[7], m.cameras[1].frames[7]
    np.testing.assert_allclose(f.camera_to_world[:3, 3], r.camera_to_world[:3, 3], atol=1e-6)
    np.testing.assert_allclose(f.camera_to_world[:3, 2], -r.camera_to_world[:3, 2], atol=1e-6)
    assert all((out / cf.image).is_file() for c in m.cameras for cf in c.frames)
