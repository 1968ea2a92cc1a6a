"""Pairs whose target a rig's second camera recorded: made at the training frames only, from the
render and warp at that camera, read as more pairs, and taken by the adaptation."""

import json
import shutil

import numpy as np
import pytest
import torch
from safetensors.numpy import load_file

from symdrive_core.cli import main
from symdrive_core.diffusion.adapt import AdaptConfig, adapt_restorer, drive_identity
from symdrive_core.diffusion.config import CycleConfig
from symdrive_core.diffusion.cycle import cycle_config
from symdrive_core.diffusion.data import PairSet, make_pairs
from symdrive_core.errors import InputError
from symdrive_core.io.images import read_image, write_image
from symdrive_core.io.ply import write_splats
from symdrive_core.scene import load_manifest
from symdrive_core.scene.camera import CameraView
from symdrive_core.splat.render import SplatRenderer
from tests.optim.conftest import synthetic_package  # noqa: F401  (fixture)

TINY = AdaptConfig(iters=3, offsets=(0.5,), cycle_offsets=(1.0,), cycle_iters=10)
QUICK_CYCLE = cycle_config(CycleConfig(iters=10))  # the cycle's fit is not what these tests look at


@pytest.fixture
def rig(synthetic_package, tmp_path):  # noqa: F811
    """The synthetic package whose +0.5 m truth a second camera recorded (the -0.5 m stays
    rendered truth), with its true Gaussians as the reconstruction."""
    root, g = synthetic_package
    root = shutil.copytree(root, tmp_path / "rig")
    data = json.loads((root / "manifest.json").read_text())
    for entry in data["ground_truth"]["lateral"]:
        if entry["offset_m"] == 0.5:
            entry["sensor"] = "front_right"
    (root / "manifest.json").write_text(json.dumps(data))
    write_splats(root / "bg.ply", g)
    return load_manifest(root), g


def test_sensor_pairs_are_the_recorded_camera_at_training_frames(rig, tmp_path):
    manifest, g = rig
    assert manifest.ground_truth["heldout_frames"] == [1, 4]  # truth at 0, 2, 4: frame 4 is held out
    out = make_pairs(manifest, g, [0.5, 1.0], tmp_path / "p.safetensors", cycle_offsets=[1.0], sensor=True,
                     cycle_config=QUICK_CYCLE, progress=False)
    data = load_file(str(out))
    assert data["sensor_frame"].tolist() == [0, 0, 2, 2] and data["sensor_offset"].tolist() == [0.5, 1.0] * 2
    assert data["sensor_view"].tolist() == [0, 0, 1, 1] and len(data["sensor_start"]) == 2
    render = SplatRenderer(g)
    at = CameraView.of_frame(manifest.cameras[0], 2).shifted(0.5)  # the second camera at frame 2
    recorded = read_image(manifest.resolve("lat/+0.5/002.png"), channels=3)
    tol = 0.5 / 255 + 1e-6
    assert np.abs(data["sensor_target"][3] / 255.0 - recorded).max() <= tol
    assert np.abs(data["sensor_start"][1] / 255.0 - render(at)).max() <= tol  # the render there: its start
    assert np.abs(data["sensor_left"][3] / 255.0 - render(at.shifted(-1.0))).max() <= tol
    assert np.abs(data["sensor_right"][3] / 255.0 - render(at.shifted(1.0))).max() <= tol
    plain = load_file(str(make_pairs(manifest, g, [0.5], tmp_path / "q.safetensors", cycle_offsets=[1.0],
                                     cycle_config=QUICK_CYCLE, progress=False)))
    assert not any(k.startswith("sensor_") for k in plain)
    with pytest.raises(ValueError, match="cycle offsets"):
        make_pairs(manifest, g, [0.5], tmp_path / "x.safetensors", sensor=True, progress=False)


def test_rendered_truth_is_no_sensor(synthetic_package, tmp_path):  # noqa: F811
    root, g = synthetic_package
    out = make_pairs(load_manifest(root), g, [0.5], tmp_path / "p.safetensors", cycle_offsets=[1.0], sensor=True,
                     cycle_config=QUICK_CYCLE, progress=False)
    assert not any(k.startswith("sensor_") for k in load_file(str(out)))
    # asked for on the command line, none there is said, before any work
    ply = tmp_path / "g.ply"
    write_splats(ply, g)
    assert main(["make-pairs", str(root), "--gaussians", str(ply), "--cycle=1", "--sensor", "--out",
                 str(tmp_path / "s.safetensors")]) == 2
    assert not (tmp_path / "s.safetensors").exists()


def test_pair_set_reads_sensor_pairs_with_their_own_start_and_warp(rig, tmp_path):
    manifest, g = rig
    path = make_pairs(manifest, g, [0.5], tmp_path / "p.safetensors", cycle_offsets=[1.0], warps=True,
                      sensor=True, cycle_config=QUICK_CYCLE, progress=False)
    data = load_file(str(path))
    pairs = PairSet(path)
    synthetic = len(data["left"])
    assert len(pairs) == synthetic + 2 and pairs.from_sensor.tolist() == [False] * synthetic + [True, True]
    for k in range(2):
        i = synthetic + k
        start = pairs.degraded[pairs.starts[i][0]]
        assert torch.equal(start, torch.from_numpy(data["sensor_start"][k]).permute(2, 0, 1).float() / 255)
        assert torch.equal(pairs.warp[pairs.warp_of[i]],
                           torch.from_numpy(data["sensor_warp"][k]).permute(2, 0, 1).float() / 255)
    without_2 = PairSet(path, holdout=[2])  # a frame left out takes its sensor pair along
    assert without_2.from_sensor.sum() == 1 and len(without_2) == len(pairs) - 2
    only_2 = PairSet(path, holdout=[2], held_out=True)
    assert only_2.from_sensor.tolist() == [False, True]
    _, target, _, start, guide = pairs.batch(64, 64, torch.Generator().manual_seed(0), 1.0)  # whole images
    assert guide.shape == (64, 4, 32, 48) and torch.isfinite(start).all()
    recorded = [pairs.target[i] for i in range(synthetic, len(pairs))]
    drawn = sum(any(torch.equal(t, r) or torch.equal(t, r.flip(-1)) for r in recorded) for t in target)
    assert 0 < drawn < 64  # the second camera's images reach the batches, beside the synthetic pairs


def test_a_sensor_image_of_the_wrong_size_is_named(rig, tmp_path):
    manifest, g = rig
    write_image(manifest.resolve("lat/+0.5/002.png"), np.zeros((8, 8, 3), np.float32))
    with pytest.raises(InputError, match=r"002.png: ground_truth.lateral \(frame 2\): image is 8x8"):
        make_pairs(manifest, g, [0.5], tmp_path / "p.safetensors", cycle_offsets=[1.0], sensor=True,
                   cycle_config=QUICK_CYCLE, progress=False)
    assert not (tmp_path / "p.safetensors").exists()


def test_the_adaptation_trains_on_the_rig_unless_told_not_to(rig, tmp_path):
    manifest, g = rig
    ply = manifest.root / "bg.ply"
    identity = drive_identity(manifest, ply)
    record = adapt_restorer(manifest, g, identity, tmp_path / "a", TINY, guided=True, progress=False)
    assert record["data"]["sensor_pairs"] == 2
    off = adapt_restorer(manifest, g, identity, tmp_path / "b", AdaptConfig(**{**TINY.__dict__, "sensor_pairs": False}),
                         guided=True, progress=False)
    assert off["data"]["sensor_pairs"] == 0


def test_the_drive_identity_covers_the_second_cameras_images(rig):
    manifest, _ = rig
    ply = manifest.root / "bg.ply"
    before = drive_identity(manifest, ply)["identity"]
    rendered = manifest.resolve("lat/-0.5/002.png")  # rendered truth: not what pairs are made from
    rendered.write_bytes(rendered.read_bytes() + b"\0")
    assert drive_identity(manifest, ply)["identity"] == before
    recorded = manifest.resolve("lat/+0.5/002.png")
    recorded.write_bytes(recorded.read_bytes() + b"\0")
    assert drive_identity(manifest, ply)["identity"] != before
