"""The restorer's adaptation to a drive: weights that record their drive, reused once made, a time
budget, and grey inputs that restore grey."""

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest
import torch
from safetensors import safe_open

from symdrive_core.cli import main
from symdrive_core.diffusion import defaults
from symdrive_core.diffusion.adapt import AdaptConfig, adapt_restorer, drive_identity, trained_drives
from symdrive_core.diffusion.models import load_builtin, load_restorer
from symdrive_core.diffusion.sampler import SamplerConfig, restore_image, to_numpy, to_tensor
from symdrive_core.diffusion.train import WEIGHTS, TrainConfig, train_restorer
from symdrive_core.io.images import read_image
from symdrive_core.io.ply import write_splats
from symdrive_core.scene import load_manifest
from symdrive_core.world.demo import DEMO_PACKAGE
from tests.diffusion.test_data_train import synthetic_pairs
from tests.optim.conftest import synthetic_package  # noqa: F401  (fixture)

TINY = AdaptConfig(iters=3, offsets=(0.5,), cycle_offsets=(1.0,), cycle_iters=10)


@pytest.fixture
def drive(synthetic_package):  # noqa: F811
    """The synthetic package with its true Gaussians as the reconstruction."""
    root, g = synthetic_package
    write_splats(root / "bg.ply", g)
    return load_manifest(root), g, root / "bg.ply"


def test_adapted_weights_record_the_drive_and_are_reused(drive, tmp_path):
    manifest, g, ply = drive
    identity = drive_identity(manifest, ply)
    out = tmp_path / "adapt"
    record = adapt_restorer(manifest, g, identity, out, TINY, guided=True, progress=False)
    assert not record["reused"] and record["steps"] == 3
    assert trained_drives(out / WEIGHTS) == [identity]
    with safe_open(str(out / "pairs.safetensors"), "np") as f:  # training frames only, with warps
        assert set(f.keys()) >= {"warp", "degraded"}
        assert json.loads(f.metadata()["frames"]) == manifest.ground_truth["train_frames"]
    adapted, shipped = load_builtin(out / WEIGHTS).net, load_builtin(defaults.GUIDED_WEIGHTS).net
    assert adapted.config == shipped.config  # the guided network, fine-tuned
    pairs = zip(adapted.state_dict().values(), shipped.state_dict().values())
    assert any(not torch.equal(a, b) for a, b in pairs)
    made = (out / WEIGHTS).stat().st_mtime_ns
    again = adapt_restorer(manifest, g, identity, out, TINY, guided=True, progress=False)
    assert again["reused"] and (out / WEIGHTS).stat().st_mtime_ns == made


def test_drive_identity_follows_content_not_names(drive, tmp_path):
    manifest, _, ply = drive
    identity = drive_identity(manifest, ply)
    copy = shutil.copytree(manifest.root, tmp_path / "elsewhere")
    assert drive_identity(load_manifest(copy), copy / "bg.ply") == identity
    image = copy / manifest.cameras[0].frames[2].image
    image.write_bytes(image.read_bytes() + b"\0")
    assert drive_identity(load_manifest(copy), copy / "bg.ply")["identity"] != identity["identity"]
    assert drive_identity(manifest, manifest.root / "points.ply")["identity"] != identity["identity"]


def test_shipped_weights_record_the_built_in_street():
    """The planner skips adaptation on the street the shipped weights were trained on."""
    demo = load_manifest(DEMO_PACKAGE)
    street = drive_identity(demo, demo.resolve(demo.background_splats))
    assert trained_drives(defaults.DEFAULT_WEIGHTS) == [street]
    assert street in trained_drives(defaults.GUIDED_WEIGHTS)  # one of the family it learnt


def test_training_stops_at_its_time_budget(tmp_path):
    pairs = synthetic_pairs(tmp_path / "p.safetensors")
    cfg = TrainConfig(steps=50, batch=2, crop=16, width=8, mults=(1, 2), max_seconds=0.0)
    record = train_restorer(pairs, tmp_path / "run", cfg, progress=False)
    assert record["steps"] == 1 and len(record["loss_every_100"]) == 1
    assert json.loads(safe_open(str(tmp_path / "run" / WEIGHTS), "np").metadata()["meta"])["steps"] == 1


def _demo_views():
    """Frame 5 of the built-in street and its neighbours, cropped small."""
    demo = load_manifest(DEMO_PACKAGE)
    cam = demo.cameras[0]
    return [read_image(demo.resolve(cam.frames[i].image), channels=3)[40:72, 100:148] for i in (4, 5, 6)]


def _spread(image: np.ndarray) -> float:
    return float((image.max(-1) - image.min(-1)).max())


def test_grey_inputs_restore_grey_and_colour_ones_keep_their_colour():
    left, centre, right = _demo_views()
    config = SamplerConfig(steps=5, n_start=4, samples=2)
    restorer = load_restorer()
    for name, net in (("default", restorer), ("guided", restorer.guided)):
        for grey in (False, True):
            views = [to_tensor(np.repeat(v.mean(-1, keepdims=True), 3, -1) if grey else v)
                     for v in (left, centre, right)]
            guide = torch.cat([views[1], torch.zeros(1, 1, *centre.shape[:2])], 1) if net.guide_channels else None
            out = to_numpy(restore_image(net, views[0], views[2], views[1], config, guide=guide))
            if grey:
                assert _spread(out) <= 0.5 / 255, name
            else:
                assert _spread(out) > 0.1, name
            assert np.abs(out - to_numpy(views[1])).mean() < 0.05, name  # the view restored, not a blank


def test_make_pairs_records_the_drive_and_warps_need_cycles(drive, tmp_path, capsys):
    manifest, _, ply = drive
    out = tmp_path / "pairs.safetensors"
    assert main(["make-pairs", str(manifest.root), "--gaussians", str(ply), "--offsets", "0.5", "--warps",
                 "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--warps" in err and "--cycle" in err and not out.exists()
    assert main(["make-pairs", str(manifest.root), "--gaussians", str(ply), "--offsets", "0.5", "--frames", "0",
                 "--out", str(out), "--quiet"]) == 0
    with safe_open(str(out), "np") as f:
        assert json.loads(f.metadata()["drive"]) == drive_identity(manifest, ply)


def test_a_grey_camera_restores_grey_views_from_renders_with_colour():
    """A reconstruction of a grey drive may render a little colour (from coloured initial points):
    the chain from a grey recorded image still restores grey views."""
    from symdrive_core.diffusion.restore import LateralChain
    from symdrive_core.scene.camera import CameraView

    demo = load_manifest(DEMO_PACKAGE)
    cam = demo.cameras[0]
    colour = read_image(demo.resolve(cam.frames[6].image), channels=3)
    recorded = np.repeat(read_image(demo.resolve(cam.frames[5].image), channels=3).mean(-1, keepdims=True), 3, -1)
    grey_but = np.clip(np.repeat(recorded[..., :1], 3, -1) + 0.02 * (colour - colour.mean(-1, keepdims=True)), 0, 1)
    chain = LateralChain(load_restorer(), lambda view: grey_but, recorded, CameraView.of_frame(cam, 5),
                         SamplerConfig(steps=5, n_start=4, samples=2))
    assert _spread(grey_but) > 2 / 255
    for offset in (0.5, -1.0):
        assert _spread(chain.restore(offset, 0.5)) <= 0.5 / 255


def test_adaptation_fits_its_strength_on_frames_it_did_not_train_on(drive, tmp_path):
    manifest, g, ply = drive
    out = tmp_path / "adapt"
    config = replace(TINY, validation_every=2)  # training frames 0, 2, 3, 5: 2 and 5 held out
    record = adapt_restorer(manifest, g, drive_identity(manifest, ply), out, config, guided=True, progress=False)
    strength = record["strength"]
    assert strength["frames"] == [2, 5] and list(record["config"]["holdout_frames"]) == [2, 5]
    assert strength["fit"]["samples"] == 2  # one pair (d = 0.5) and one cycle start per held-out frame
    assert 0.0 <= strength["strength"] <= 1.0
    assert load_builtin(out / WEIGHTS).strength == pytest.approx(strength["strength"])
    assert load_builtin(out / WEIGHTS).keep_warp is strength["keep_warp"] is strength["fit"]["keep_warp"]
    assert trained_drives(out / WEIGHTS) == [drive_identity(manifest, ply)]  # the rest of the record stays
    assert json.loads((out / "restorer.json").read_text())["strength"] == strength


def test_too_few_frames_to_hold_out_keep_the_full_strength(drive, tmp_path):
    manifest, g, ply = drive
    out = tmp_path / "adapt"
    record = adapt_restorer(manifest, g, drive_identity(manifest, ply), out, TINY, guided=True, progress=False)
    assert record["strength"] == {"strength": 1.0, "keep_warp": True, "frames": [], "fit": None}
    assert list(record["config"]["holdout_frames"]) == [] and load_builtin(out / WEIGHTS).strength == 1.0
