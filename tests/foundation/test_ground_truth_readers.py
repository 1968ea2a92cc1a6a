import numpy as np

from symdrive_core.scene import parse_manifest
from symdrive_core.scene.ground_truth import lateral_views, split_frames
from tests.conftest import manifest_dict


def _manifest(tmp_path, gt=None, n=10):
    d = manifest_dict(n_frames=n)
    if gt is not None:
        d["ground_truth"] = gt
    return parse_manifest(d, tmp_path / "manifest.json")


def test_split_uses_the_packages_lists(tmp_path):
    m = _manifest(tmp_path, {"train_frames": [0, 1, 3], "heldout_frames": [2]}, n=4)
    assert split_frames(m) == ([0, 1, 3], [2])


def test_split_falls_back_to_every_kth(tmp_path):
    train, held = split_frames(_manifest(tmp_path), holdout_every=4)
    assert held == [2, 6] and train == [0, 1, 3, 4, 5, 7, 8, 9]


def test_lateral_views_move_the_camera_to_its_right(tmp_path):
    gt = {"lateral": [{"offset_m": 1.5, "camera": "front", "frames": {"2": "a.png", "0": "b.png"}},
                      {"offset_m": -0.5, "camera": "front", "frames": {"1": "c.png"}}]}
    m = _manifest(tmp_path, gt, n=3)
    views = lateral_views(m)
    assert [(v.offset_m, v.frame, v.image) for v in views] == [(1.5, 0, "b.png"), (1.5, 2, "a.png"), (-0.5, 1, "c.png")]
    for v in views:
        base = m.cameras[0].frames[v.frame].camera_to_world
        moved = v.camera_to_world[:3, 3] - base[:3, 3]
        assert np.allclose(moved, v.offset_m * base[:3, 0])
        assert np.allclose(v.world_to_camera @ v.camera_to_world, np.eye(4))
