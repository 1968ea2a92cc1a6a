"""Recorded camera poses refined with the Gaussians: the world moved by a frame's inverse
correction renders what the corrected camera sees, its gradient reaches the correction, frames
without a training view take the correction between their neighbours', poses that the recording
put off come back nearer the truth, and the refined poses go back into the package with the
recording's kept."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from symdrive_core import conventions
from symdrive_core.optim.camera_refine import (
    CameraRefinement,
    corrected_layers,
    read_cameras,
    recorded_views,
    with_refined_cameras,
)
from symdrive_core.optim.config import CameraRefineConfig
from symdrive_core.optim.reconstruct import ReconstructConfig, reconstruct
from symdrive_core.optim.views import load_views
from symdrive_core.rotations import rotation_vector_matrix
from symdrive_core.scene import load_manifest
from symdrive_core.splat.compose import Layer, compose_layers
from symdrive_core.splat.render import render_layers
from symdrive_core.splat.tensors import GaussianTensors
from tests.conftest import look_at_c2w
from tests.optim.conftest import H, W, true_scene, write_package

K = conventions.intrinsics_from_fov(W, H, np.deg2rad(70))


def _refinement(frames=(0, 2, 5), cfg=CameraRefineConfig(enabled=True)) -> CameraRefinement:
    centres = {f: np.array([0.4 * f, 0.0, 1.5]) for f in frames}
    return CameraRefinement(centres, 8, cfg, start=0)


def _set(c: CameraRefinement, frame: int, w, d) -> None:
    with torch.no_grad():
        c.rotation[c.row[frame]] = torch.tensor(w, dtype=torch.float64)
        c.translation[c.row[frame]] = torch.tensor(d, dtype=torch.float64)


def test_the_world_moved_back_renders_what_the_moved_camera_sees():
    c = _refinement()
    _set(c, 2, [0.01, -0.02, 0.03], [0.05, -0.1, 0.02])
    c2w = look_at_c2w((0.8, 0.0, 1.5), (0.8, 6.0, 1.2))
    g = GaussianTensors.from_gaussians(true_scene())
    Kt = torch.tensor(K, dtype=torch.float32)
    moved = c.camera_to_world(2, c2w)
    want = render_layers([Layer(g)], torch.tensor(conventions.invert_rigid(moved)), Kt, W, H)["rgb"]
    with torch.no_grad():
        got = render_layers(corrected_layers([Layer(g)], c.world_inverse(2)),
                            torch.tensor(conventions.invert_rigid(c2w)), Kt, W, H)["rgb"]
    assert float((want - got).abs().max()) < 1e-4
    R = rotation_vector_matrix([0.01, -0.02, 0.03])  # about the frame's first camera centre
    centre = np.array([0.8, 0.0, 1.5])
    expected = np.eye(4)
    expected[:3, :3], expected[:3, 3] = R, centre - R @ centre + [0.05, -0.1, 0.02]
    np.testing.assert_allclose(moved, expected @ c2w, atol=1e-12)


def test_the_correction_takes_the_gradient_of_what_it_moves():
    """Finite differences in float64 of a function of the composed (camera-relative) positions."""
    c = _refinement()
    g = GaussianTensors.from_gaussians(true_scene(), dtype=torch.float64)
    w2c = torch.tensor(conventions.invert_rigid(look_at_c2w((0.8, 0.0, 1.5), (0.8, 6.0, 1.2))))
    weights = torch.randn(len(g), 3, dtype=torch.float64, generator=torch.Generator().manual_seed(0))

    def value():
        composed = compose_layers(corrected_layers([Layer(g)], c.world_inverse(2)), w2c,
                                  torch.tensor(K, dtype=torch.float64), W, H, cull=False, sh_backend="torch")
        return (composed.means * weights).sum() + composed.quats.sum()

    _set(c, 2, [0.004, -0.003, 0.01], [0.02, 0.01, -0.03])
    value().backward()
    grads = torch.cat([c.rotation.grad[c.row[2]], c.translation.grad[c.row[2]]])
    eps = 1e-6
    for k in range(6):
        p, i = (c.rotation, k) if k < 3 else (c.translation, k - 3)
        with torch.no_grad():
            p[c.row[2], i] += eps
            up = value()
            p[c.row[2], i] -= 2 * eps
            down = value()
            p[c.row[2], i] += eps
        assert float(grads[k]) == pytest.approx(float((up - down) / (2 * eps)), rel=1e-5, abs=1e-6)


def test_frames_without_a_view_take_the_correction_between_their_neighbours():
    c = _refinement(frames=(0, 2, 5))
    _set(c, 2, [0.0, 0.0, 0.01], [0.3, 0.0, 0.0])
    _set(c, 5, [0.0, 0.0, 0.04], [0.0, 0.6, 0.0])
    w, d, _ = c._vectors(4)  # two thirds of the way from 2 to 5
    np.testing.assert_allclose(w.numpy(), [0.0, 0.0, 0.03], atol=1e-12)
    np.testing.assert_allclose(d.numpy(), [0.1, 0.4, 0.0], atol=1e-12)
    w7, d7, _ = c._vectors(7)  # past the last: the last one's
    np.testing.assert_allclose(w7.numpy(), [0.0, 0.0, 0.04], atol=1e-12)
    assert not w.requires_grad and c._vectors(2)[0].requires_grad


def _perturbed(root, frames, angle_rad, shift_m):
    """The package with the recorded pose of ``frames`` turned about its camera centre and shifted
    (its image still from the true pose)."""
    m = load_manifest(root)
    truth = [cf.camera_to_world.copy() for cf in m.cameras[0].frames]
    for f in frames:
        cf = m.cameras[0].frames[f]
        turn = np.eye(4)
        turn[:3, :3] = rotation_vector_matrix([0.0, 0.0, angle_rad * (-1) ** f])
        c2w = cf.camera_to_world @ turn
        c2w[:3, 3] += [shift_m * (-1) ** f, 0.0, 0.0]
        cf.camera_to_world, cf.world_to_camera = c2w, conventions.invert_rigid(c2w)
    m.save()
    return truth


def _angle_deg(a, b) -> float:
    R = a[:3, :3].T @ b[:3, :3]
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))))


PERTURBED = (2, 5)  # of the training frames 0, 2, 3, 5, 6 (1, 4, 7 held out)


@pytest.fixture(scope="module")
def refined(tmp_path_factory):
    root, _ = write_package(tmp_path_factory.mktemp("cams") / "pkg", n_frames=8, offsets=())
    truth = _perturbed(root, PERTURBED, np.radians(1.5), 0.06)
    m = load_manifest(root)
    cfg = ReconstructConfig(iters=300, seed=0, camera_refine=CameraRefineConfig(enabled=True, lr_rad=2e-3,
                                                                                lr_m=8e-3))
    out = tmp_path_factory.mktemp("fit")
    return m, truth, reconstruct(m, out, cfg, progress=False), out


def test_poses_the_recording_put_off_come_back_nearer_the_truth(refined):
    m, truth, result, out = refined
    before = [_angle_deg(truth[f], m.cameras[0].frames[f].camera_to_world) for f in PERTURBED]
    after = [_angle_deg(truth[f], result.cameras["front"][f]) for f in PERTURBED]
    assert all(a < b for a, b in zip(after, before)) and np.mean(after) < 0.6 * np.mean(before), (before, after)
    np.testing.assert_allclose(read_cameras(out)["front"][3], result.cameras["front"][3], atol=1e-8)
    assert result.metrics["camera_correction"]["mean_deg"] > 0.3


def test_refined_poses_go_back_with_the_recordings_kept(refined):
    m = load_manifest(refined[0].root)
    result = refined[2]
    recorded = [cf.camera_to_world.copy() for cf in m.cameras[0].frames]
    with_refined_cameras(m, result.cameras)
    m.save()
    back = load_manifest(m.root)
    for f, cf in enumerate(back.cameras[0].frames):
        np.testing.assert_allclose(cf.recorded_camera_to_world, recorded[f], atol=1e-12)
        np.testing.assert_allclose(cf.camera_to_world, result.cameras["front"][f], atol=1e-9)
    with_refined_cameras(back, {"front": [np.eye(4)] * len(back.frames)})  # a second refinement
    assert np.allclose(back.cameras[0].frames[2].recorded_camera_to_world, recorded[2])
    views = load_views(back, [0, 2], depth=False)
    again = recorded_views(back, views)
    np.testing.assert_allclose(again[1].viewmat.double().numpy(), conventions.invert_rigid(recorded[2]), atol=1e-5)


def test_off_by_default_and_from_the_command_line(command_config, synthetic_package):
    assert not ReconstructConfig().camera_refine.enabled
    root, _ = synthetic_package
    assert command_config([str(root), "--refine-cameras"]).camera_refine.enabled
    assert not command_config([str(root)]).camera_refine.enabled


def test_a_recorded_pose_that_is_not_rigid_is_refused_by_name(synthetic_package, tmp_path):
    import json
    import shutil

    from symdrive_core.scene import ManifestError

    root, _ = synthetic_package
    copy = tmp_path / "pkg"
    shutil.copytree(root, copy)
    doc = json.loads((copy / "manifest.json").read_text())
    bad = np.eye(4)
    bad[0, 0] = 2.0
    doc["cameras"][0]["frames"][1]["recorded_camera_to_world"] = bad.tolist()
    (copy / "manifest.json").write_text(json.dumps(doc))
    with pytest.raises(ManifestError, match=r"cameras\[0\]\.frames\[1\]\.recorded_camera_to_world"):
        load_manifest(copy)
    doc["cameras"][0]["frames"][1]["recorded_camera_to_world"] = [[1, 0, 0]] * 4
    (copy / "manifest.json").write_text(json.dumps(doc))
    with pytest.raises(ManifestError, match="recorded_camera_to_world"):
        load_manifest(copy)
