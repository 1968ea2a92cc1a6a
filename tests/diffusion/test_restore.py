import numpy as np
import pytest

from symdrive_core import conventions
from symdrive_core.diffusion.restore import LateralChain, chain_positions, method_step
from symdrive_core.diffusion.sampler import SamplerConfig
from symdrive_core.scene.camera import CameraView
from tests.optim.conftest import synthetic_package  # noqa: F401  (fixture)


class OffsetRenderer:
    """A stand-in renderer whose image encodes the camera's lateral offset in its pixel value
    (the recorded camera sits at the origin looking down +z, so the offset is its x position)."""

    def __call__(self, view):
        offset = float(view.camera_to_world[0, 3])
        return np.full((view.height, view.width, 3), 0.5 + offset / 10.0, np.float32)


class OffsetWarper:
    """A stand-in warper: the render plus 0.25, recording which frame it warps for."""

    class config:
        min_alpha = 0.5

    def __init__(self):
        self.frames = []

    def warp(self, frame, K, c2w, width, height, raw, depth):
        from types import SimpleNamespace

        self.frames.append(frame)
        return SimpleNamespace(image=raw + 0.25)


class DepthOffsetRenderer(OffsetRenderer):
    def depth(self, view, min_alpha):
        return np.zeros((view.height, view.width))


class RecordingRestorer:
    """Returns (left + right) / 2 after recording which views it was given (in pixel values)."""

    def __init__(self):
        from symdrive_core.diffusion.latent import PixelSpace

        self.latent = PixelSpace()
        self.pairs = []

    def time_shift(self, shape):
        return 0.0

    def velocity(self, z, t, left, right):
        self.pairs.append((round(float(left.mean() + 1) / 2, 4), round(float(right.mean() + 1) / 2, 4)))
        y = (left + right) / 2  # exact velocity of a point mass at the mean of the two views
        return (z - y) / t.reshape(-1, 1, 1, 1)


def chain(step_sampler=None):
    step_sampler = step_sampler or SamplerConfig(steps=2, n_start=0)
    restorer = RecordingRestorer()
    recorded = np.full((4, 6, 3), 0.5, np.float32)
    return restorer, LateralChain(
        restorer, OffsetRenderer(), recorded, CameraView(np.eye(4), np.eye(3), 6, 4), step_sampler
    )


def value(offset):
    return round(0.5 + offset / 10.0, 4)


def test_chain_positions():
    assert chain_positions(3.0, 0.5) == pytest.approx([0.5, 1, 1.5, 2, 2.5, 3])
    assert chain_positions(-1.5, 1.0) == pytest.approx([-0.75, -1.5])
    assert chain_positions(0.5, 1.0) == pytest.approx([0.5])
    assert method_step("ar_d0.5") == 0.5 and method_step("single_view") == 0.0
    assert method_step("geo_ar_d1") == 1.0 and method_step("geo_single_view") == 0.0
    with pytest.raises(ValueError):
        method_step("ar_dx")


def test_right_chain_conditions_on_the_previous_view_and_the_render_beyond():
    restorer, c = chain()
    c.restore(1.0, 0.5)
    firsts = [restorer.pairs[0], restorer.pairs[2]]  # 2 sampler steps per view
    assert firsts[0] == (0.5, value(1.0))  # (I_0, render(2d)) -> I_d
    restored_d = (0.5 + value(1.0)) / 2
    assert firsts[1] == (round(restored_d, 4), value(1.5))  # (I_d, render(3d)) -> I_2d


def test_left_chain_swaps_the_conditions():
    restorer, c = chain()
    c.restore(-0.5, 0.5)
    assert restorer.pairs[0] == (value(-1.0), 0.5)


def test_guided_chain_takes_the_warps_for_the_renders():
    restorer = RecordingRestorer()
    warper = OffsetWarper()
    recorded = np.full((4, 6, 3), 0.5, np.float32)
    c = LateralChain(restorer, DepthOffsetRenderer(), recorded, CameraView(np.eye(4), np.eye(3), 6, 4),
                     SamplerConfig(steps=1, n_start=0), warper, frame=7)
    c.by_method(-0.5, "geo_ar_d0.5")
    assert restorer.pairs[0] == (value(-1.0) + 0.25, 0.5)  # the warp at -2d is the far condition
    c.by_method(1.0, "geo_single_view")
    assert restorer.pairs[1] == (value(1.0) + 0.25, value(1.0) + 0.25)
    assert np.allclose(c.by_method(3.0, "warp"), value(3.0) + 0.25) and c.samples == 2
    assert set(warper.frames) == {7}
    c.by_method(-0.5, "ar_d0.5")  # unguided: its own restoration, from the renders
    assert restorer.pairs[2] == (value(-1.0), 0.5)


def test_single_view_duplicates_the_render_at_the_target():
    restorer, c = chain()
    c.restore(2.0, 0.0)
    assert restorer.pairs[0] == (value(2.0), value(2.0))


def test_chains_share_their_prefix_and_offset_zero_is_the_recording():
    _, c = chain()
    for off in (0.5, 1.0, 1.5, 2.0, 3.0):
        c.restore(off, 0.5)
    assert c.samples == 6  # 0.5 .. 3.0 each sampled once (2.5 on the way to 3.0)
    assert c.restore(0.0, 0.5) is c.recorded


def test_init_is_the_render_at_the_target():
    """With N_start at the last step, one Euler step from the noised target render."""
    restorer, c = chain(SamplerConfig(steps=2, n_start=1, seed=0))
    out = c.restore(0.5, 0.5)
    # t = 0.5: z = 0.5 render(0.5) + 0.5 eps; the step to 0 lands on the oracle's target
    assert np.allclose(out, (0.5 + value(1.0)) / 2, atol=1e-5)
    assert len(restorer.pairs) == 1


def test_camera_shift_matches_conventions():
    c2w = np.eye(4)
    cam = CameraView(conventions.invert_rigid(c2w), np.eye(3), 4, 4)
    assert np.allclose(cam.shifted(2.0).camera_to_world, conventions.lateral_shift(c2w, 2.0))
    assert cam.shifted(2.0).K is cam.K and (cam.shifted(2.0).width, cam.shifted(2.0).height) == (4, 4)


def test_lateral_views_of_every_frame_reuse_the_scored_chains(synthetic_package):  # noqa: F811
    """Refinement's views come from one chain per frame; chains built while scoring are reused."""
    from symdrive_core.diffusion.restore import restore_lateral_views
    from symdrive_core.eval.restoration import run_lateral_restoration
    from symdrive_core.scene import load_manifest

    root, truth = synthetic_package
    manifest = load_manifest(root)
    restorer = RecordingRestorer()
    sampler = SamplerConfig(steps=1, n_start=0)
    scored = run_lateral_restoration(manifest, truth, restorer, methods=("ar_d0.5",), sampler=sampler,
                                     frames=[0], progress=False)
    assert scored.chains[0].samples == 2  # +-0.5 m
    views = restore_lateral_views(manifest, truth, restorer, [0, 3], [1.0, 0.5], 0.5, sampler=sampler,
                                  chains=scored.chains, progress=False)
    assert [(v.frame, v.offset_m) for v in views] == [
        (f, o) for f in (0, 3) for o in (-0.5, 0.5, -1.0, 1.0)
    ]
    assert scored.chains[0].samples == 4 and scored.chains[3].samples == 4  # frame 0 sampled +-0.5 once
    scored_images = {v.offset_m: v.image for v in scored.views["ar_d0.5"]}
    assert all(v.image is scored_images[v.offset_m] for v in views[:2])  # the very restorations scored
    shifted = conventions.lateral_shift(manifest.cameras[0].frames[3].camera_to_world, 1.0)
    assert np.allclose(views[-1].camera_to_world, shifted)
    assert np.allclose(views[-1].world_to_camera @ shifted, np.eye(4), atol=1e-9)
