"""Rigs and frames: several cameras on shared frames, order by name or timestamp, held-out split."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.errors import InputError
from symdrive_core.importers.frames import View, frame_times, group_views, natural_key, split_heldout
from symdrive_core.scene import load_manifest

from .demo_formats import CAMERA_HEIGHT, World, demo_world, link_images, write_colmap

pytest.importorskip("pycolmap")


def test_split_like_the_demo():
    train, held = split_heldout(30, 5)
    assert held == [2, 7, 12, 17, 22, 27] and len(train) == 24
    assert split_heldout(4, None) == ([0, 1, 2, 3], [])


def test_natural_order():
    assert sorted(["img10.png", "img9.png", "img100.png"], key=natural_key) == ["img9.png", "img10.png", "img100.png"]


def test_digits_that_are_no_decimal_number_sort_as_text():
    """A superscript or circled digit is a digit to str.isdigit but no number to int()."""
    assert sorted(["2", "\u00b2", "1\u00b2", "10"], key=natural_key) == ["1\u00b2", "2", "10", "\u00b2"]


def test_frames_without_recorded_times_are_timed_by_their_numbers_so_a_gap_stays_a_gap():
    assert frame_times(["000000", "000001", "000003", "000004"], 10.0) == [0.0, 0.1, 0.3, 0.4]
    assert frame_times(["data/0000000007", "data/0000000009"], 2.0) == [0.0, 1.0]  # from the first frame
    # numbers that do not increase along the frames (or a name without one): one period apart
    assert frame_times(["b_2", "a_2", "c"], 10.0) == [0.0, 0.1, 0.2]


def view(name: str, timestamp: float | None = None) -> View:
    return View(name, np.diag([100.0, 100.0, 1.0]), 64, 48, np.eye(4), Path("images.txt"), f"images[{name}]",
                timestamp=timestamp)


def test_two_frames_at_one_instant_are_refused_naming_the_file_and_the_view():
    with pytest.raises(InputError) as err:
        group_views([view("0001.png", 0.0), view("0002.png", 0.5), view("0003.png", 0.5)])
    assert "images.txt: images[0003.png]: frame 0003.png has the time of frame 0002.png" in str(err.value)
    grouped = group_views([view("0002.png", 0.2), view("0001.png", 0.1)])  # by time, not name: fine
    assert grouped.frame_keys == ["0001.png", "0002.png"] and grouped.timestamps == [0.1, 0.2]


def test_a_frame_one_camera_lacks_is_left_out_and_its_images_listed():
    views = [view(f"left/{i:04d}.png") for i in range(4)] + [view(f"right/{i:04d}.png") for i in (0, 1, 3)]
    grouped = group_views(views)
    assert grouped.frame_keys == ["0000", "0001", "0003"] and grouped.timestamps == [0.0, 0.1, 0.3]
    assert [v.name for v in grouped.left_out] == ["left/0002.png"]


def import_rig(tmp_path, capsys, without: str | None = None):
    """The demo world seen by a front and a rear camera, as a COLMAP model laid out by camera
    folder (``without``: an image left out of it), imported; (manifest, frames, stderr)."""
    w = demo_world(seed=5, max_splats=2000)
    turn = np.diag([-1.0, 1.0, -1.0, 1.0])  # the rear camera: the front one turned about its y axis
    n = len(w.names)
    names = [f"front/{i:04d}.png" for i in range(n)] + [f"rear/{i:04d}.png" for i in range(n)]
    keep = [name != without for name in names]
    rig = World(S=w.S, names=[x for x, k in zip(names, keep) if k],
                images=[x for x, k in zip(w.images + w.images, keep) if k], K=w.K, width=w.width, height=w.height,
                c2w=np.concatenate([w.c2w, w.c2w @ turn])[keep], c2w_demo=w.c2w_demo, splats=w.splats,
                points=w.points, colors=w.colors)
    model = write_colmap(rig, tmp_path / "sparse")
    link_images(rig, tmp_path / "images")
    out = tmp_path / "pkg"
    rc = main(["import", "colmap", str(model), "--images", str(tmp_path / "images"), "--out", str(out),
               "--camera-height", str(CAMERA_HEIGHT), "--copy-images", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 0, err
    return load_manifest(out), n, err


def test_a_rig_frame_one_camera_lacks_is_left_out_and_said(tmp_path, capsys):
    m, n, err = import_rig(tmp_path, capsys, without="rear/0005.png")
    assert len(m.frames) == n - 1
    assert "warning: 1 image(s) left out, of frames not every camera recorded: front/0005.png" in err
    assert m.source["images_left_out"] == ["front/0005.png"]
    assert m.frames[5].timestamp - m.frames[4].timestamp == pytest.approx(0.2)  # frame 6 two periods after frame 4


def test_rig_folders_become_cameras_on_shared_frames(tmp_path, capsys):
    m, n, err = import_rig(tmp_path, capsys)
    out = tmp_path / "pkg"
    assert "left out" not in err and "images_left_out" not in m.source
    assert [c.name for c in m.cameras] == ["front", "rear"] and len(m.frames) == n
    f, r = m.cameras[0].frames[7], m.cameras[1].frames[7]
    np.testing.assert_allclose(f.camera_to_world[:3, 3], r.camera_to_world[:3, 3], atol=1e-6)
    np.testing.assert_allclose(f.camera_to_world[:3, 2], -r.camera_to_world[:3, 2], atol=1e-6)
    assert all((out / cf.image).is_file() for c in m.cameras for cf in c.frames)
