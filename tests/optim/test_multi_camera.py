"""A rig of cameras reconstructs as one drive: every camera that recorded all its frames trains, held-out
frames are held out from each, and each camera is scored."""

import dataclasses
import json

import numpy as np
import pytest
import torch

from symdrive_core import conventions
from symdrive_core.eval.views import evaluate_heldout
from symdrive_core.io.images import write_image
from symdrive_core.optim.reconstruct import ReconstructConfig, reconstruct
from symdrive_core.optim.views import cameras_left_out, load_views, training_cameras
from symdrive_core.scene import Camera, CameraFrame, load_manifest
from symdrive_core.scene.camera import CameraView
from symdrive_core.scene.ground_truth import split_frames
from symdrive_core.splat.render import render_scene
from symdrive_core.splat.tensors import GaussianTensors
from tests.optim.moving_box import N_FRAMES, H, W, box_pose, camera_c2w, street, true_box, write_moving_box

BASELINE_M = 1.2  # the second camera's place to the right of the first (a wide stereo rig)


def add_camera(root, name: str, offset_m: float, images: bool = True, colours=None):
    """The package at ``root`` with a camera ``offset_m`` to the right of ``front``, its images
    rendered from the true scene (or none: a camera that recorded nothing), through ``colours``
    (an image -> image function: the camera's own exposure) where given."""
    m = load_manifest(root)
    bg, car = GaussianTensors.from_gaussians(street()), GaussianTensors.from_gaussians(true_box())
    K = m.cameras[0].frames[0].K
    frames = []
    for i in range(N_FRAMES):
        c2w = conventions.lateral_shift(camera_c2w(i), offset_m)
        image = None
        if images:
            with torch.no_grad():
                out = render_scene(bg, [(car, box_pose(i), 1)], CameraView(conventions.invert_rigid(c2w), K, W, H))
            image = f"{name}/{i:03d}.png"
            rgb = out["rgb"].clamp(0, 1).numpy()
            write_image(root / image, rgb if colours is None else np.clip(colours(rgb), 0, 1))
        frames.append(CameraFrame(K, c2w, conventions.invert_rigid(c2w), image))
    m.cameras.append(Camera(name, W, H, frames))
    m.save()
    return load_manifest(root)


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """The moving box seen by ``front`` and ``right``, fitted on both and on ``front`` alone."""
    root, *_ = write_moving_box(tmp_path_factory.mktemp("rig") / "pkg")
    m = add_camera(root, "right", BASELINE_M)
    front_only = dataclasses.replace(m, cameras=[m.cameras[0], dataclasses.replace(
        m.cameras[1], frames=[dataclasses.replace(cf, image=None) for cf in m.cameras[1].frames])])
    cfg = ReconstructConfig(iters=500, densify_from=100, densify_every=100, sky_points=0, actor_points=600,
                            checkpoint_every=10_000, sh_degree=0)
    both = reconstruct(m, root / "both", cfg, progress=False)
    one = reconstruct(front_only, root / "one", cfg, progress=False)
    return m, both, one


def test_every_camera_that_recorded_images_trains(tmp_path):
    root, *_ = write_moving_box(tmp_path / "pkg")
    add_camera(root, "right", BASELINE_M)
    m = add_camera(root, "virtual", -2.0, images=False)
    m = add_camera(root, "gappy", -1.0)
    m.camera("gappy").frames[3].image = None  # a camera that missed a frame
    assert [c.name for c in training_cameras(m)] == ["front", "right"]
    assert cameras_left_out(m) == {"virtual": "no images", "gappy": "no image at frame 3 (1 of 16 frames)"}
    train = split_frames(m)[0][:3]
    views = load_views(m, train)
    assert [(v.frame, v.camera_name) for v in views] == [(f, c) for f in train for c in ("front", "right")]
    assert [v.camera_name for v in load_views(m, train, "right")] == ["right"] * 3


def test_a_rig_trains_on_each_camera_and_scores_each(rig):
    m, both, one = rig
    train, heldout = split_frames(m)
    assert both.metrics["cameras"] == ["front", "right"] and both.metrics["views"] == 2 * len(train)
    assert one.metrics["cameras"] == ["front"] and one.metrics["views"] == len(train)
    scores = evaluate_heldout(m, both.gaussians, heldout, actors=both.actors)
    assert set(scores["cameras"]) == {"front", "right"}
    per = [scores["cameras"][c]["psnr_heldout"] for c in ("front", "right")]
    assert scores["psnr_heldout"] == pytest.approx(np.mean(per), abs=2e-3)


def test_the_second_camera_is_seen_better_by_the_fit_that_trained_on_it(rig):
    m, both, one = rig
    heldout = split_frames(m)[1]
    right_both = evaluate_heldout(m, both.gaussians, heldout, "right", actors=both.actors)["psnr_heldout"]
    right_one = evaluate_heldout(m, one.gaussians, heldout, "right", actors=one.actors)["psnr_heldout"]
    assert right_both > right_one + 1.0


def _with_reconstruction(rig):
    """The rig's package pointing at its two-camera reconstruction, restoring views 1 m aside."""
    m, both, _ = rig
    m.background_splats = (both.output / "background.ply").relative_to(m.root).as_posix()
    m.actor("car_1").splats = (both.output / "actors" / "car_1.ply").relative_to(m.root).as_posix()
    m.effects.lateral_offsets = [1.0]
    m.save()
    return m


def test_a_run_renders_restores_and_refines_every_camera(rig, tmp_path):
    """(The restorer's adaptation, the run's slowest default stage, is tested on one camera.)"""
    from symdrive_core.cli import main

    m = _with_reconstruction(rig)
    out = tmp_path / "out"
    assert main(["run", str(m.root), "--out", str(out), "--quiet", "--frames", "2,6", "--no-adapt"]) == 0
    stages = {s["name"]: s for s in json.loads((out / "report.json").read_text())["stages"]}
    assert stages["refine"]["ran"] and stages["restore"]["ran"]
    for cam in ("front", "right"):
        assert sorted(p.name for p in (out / "render" / cam).glob("*.png")) == ["000002.png", "000006.png"]
        assert sorted(p.name for p in (out / "restore" / cam / "+1").glob("*.png")) == ["000002.png", "000006.png"]


def test_a_run_keeps_to_the_cameras_named(rig, tmp_path, capsys):
    from symdrive_core.cli import main

    m = _with_reconstruction(rig)
    out = tmp_path / "out"
    assert main(["run", str(m.root), "--out", str(out), "--quiet", "--frames", "2", "--no-adapt", "--no-refine",
                 "--cameras", "right"]) == 0
    assert sorted(p.relative_to(out).as_posix() for p in out.glob("re*/**/*.png")) == [
        "render/right/000002.png", "restore/right/+1/000002.png"]  # the manifest's offsets are signed
    report = json.loads((out / "report.json").read_text())
    assert report["cameras"] == ["right"]
    capsys.readouterr()
    assert main(["plan", str(m.root), "--cameras", "right,rear"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "cameras" in err and "'rear' is not in the package (front, right)" in err
