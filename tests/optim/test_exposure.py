"""Each camera's colours learnt with the Gaussians: a rig whose second camera records brighter
and warmer is fitted in the first camera's colours, its transform found, and its held-out views
scored through it; the transforms resume exactly."""

import numpy as np
import pytest
import torch

from symdrive_core.eval.views import evaluate_heldout
from symdrive_core.optim.exposure import Exposure, read_exposure, recorded_colours
from symdrive_core.optim.reconstruct import ReconstructConfig, reconstruct
from symdrive_core.optim.views import View
from symdrive_core.scene.ground_truth import split_frames
from tests.optim.moving_box import write_moving_box
from tests.optim.test_multi_camera import BASELINE_M, add_camera

GAIN = np.array([1.12, 1.05, 0.95])  # the second camera: brighter, warmer
BIAS = np.array([0.02, 0.0, -0.01])


def _view(camera: str, frame: int = 0) -> View:
    return View(frame, torch.eye(3), torch.eye(4), torch.zeros(2, 2, 3), None, 2, 2, camera)


def test_which_views_get_a_transform():
    views = [_view(c, f) for f in range(3) for c in ("left", "right")]
    assert Exposure.of(views, "off", 1e-3) is None
    assert Exposure.of([_view("left", f) for f in range(3)], "camera", 1e-3) is None  # one camera: nothing to fit
    per_camera = Exposure.of(views, "camera", 1e-3)
    assert per_camera.reference == "left" and list(per_camera.transforms) == ["right"]
    assert per_camera.penalty(6) is None
    per_view = Exposure.of(views, "frame", 1e-3)
    assert len(per_view.transforms) == 6 and float(per_view.penalty(6).detach()) == 0.0
    rgb = torch.rand(2, 2, 3)
    assert torch.equal(per_camera.apply(rgb, _view("left")), rgb)
    assert torch.allclose(per_camera.apply(rgb, _view("right")), rgb)  # the identity at the start
    with pytest.raises(ValueError, match="exposure mode"):
        Exposure("sometimes", "left", [], 1e-3)


def test_transforms_resume_with_their_moments(tmp_path):
    views = [_view(c) for c in ("left", "right")]
    e = Exposure.of(views, "camera", 1e-2)
    for it in range(3):
        e.zero_grad()
        loss = (e.apply(torch.full((2, 2, 3), 0.5), _view("right")) - 0.7).pow(2).sum()
        loss.backward()
        e.step_at(it)
    e.checkpoint(tmp_path)
    back = Exposure.of(views, "camera", 1e-2)
    back.resume(tmp_path)
    assert torch.equal(back.transforms["right"], e.transforms["right"])
    state, saved = back.opt.state[back.transforms["right"]], e.opt.state[e.transforms["right"]]
    assert torch.equal(state["exp_avg"], saved["exp_avg"]) and int(state["step"]) == 3


@pytest.fixture(scope="module")
def tinted_rig(tmp_path_factory):
    root, *_ = write_moving_box(tmp_path_factory.mktemp("tinted") / "pkg")
    m = add_camera(root, "right", BASELINE_M, colours=lambda rgb: rgb * GAIN + BIAS)
    cfg = ReconstructConfig(iters=500, densify_from=100, densify_every=100, sky_points=0, actor_points=600,
                            checkpoint_every=10_000, sh_degree=0, lr_exposure=5e-3)
    fitted = reconstruct(m, root / "fitted", cfg, progress=False)
    plain = reconstruct(m, root / "plain", ReconstructConfig(**{**cfg.__dict__, "exposure": "off"}), progress=False)
    return m, fitted, plain


def test_a_brighter_camera_is_fitted_through_its_own_transform(tinted_rig):
    m, fitted, plain = tinted_rig
    assert set(fitted.exposure) == {"right"} and plain.exposure == {}
    assert read_exposure(fitted.output)["right"] == pytest.approx(fitted.exposure["right"], abs=1e-5)
    A = fitted.exposure["right"]
    assert np.allclose(np.diag(A[:, :3]), GAIN, atol=0.05) and np.allclose(A[:, 3], BIAS, atol=0.03)
    heldout = split_frames(m)[1]
    ours = evaluate_heldout(m, fitted.gaussians, heldout, actors=fitted.actors, exposure=fitted.exposure)["cameras"]
    theirs = evaluate_heldout(m, plain.gaussians, heldout, actors=plain.actors)["cameras"]
    assert ours["right"]["psnr_heldout"] > theirs["right"]["psnr_heldout"] + 1.0
    assert ours["front"]["psnr_heldout"] > theirs["front"]["psnr_heldout"] - 0.3  # the scene keeps the first's colours


def test_a_render_is_put_in_a_cameras_colours_and_clipped():
    img = np.full((2, 2, 3), 0.9, np.float32)
    A = np.concatenate([np.diag(GAIN), BIAS[:, None]], 1)
    out = recorded_colours(img, A)
    assert np.allclose(out, np.clip(0.9 * GAIN + BIAS, 0, 1)) and recorded_colours(img, None) is img


def test_a_run_on_a_package_reconstructed_before_scores_through_the_transforms_beside_its_splats(tinted_rig, tmp_path):
    """``symdrive run`` on a package whose background ``symdrive reconstruct`` linked earlier reads
    the cameras' transforms written beside its ``background.ply``; a run that fitted its own keeps
    those; a broken record is refused naming the field."""
    from types import SimpleNamespace

    from symdrive_core.errors import InputError
    from symdrive_core.pipeline.stages import exposure

    m, fitted, _ = tinted_rig
    m.background_splats = (fitted.output / "background.ply").relative_to(m.root).as_posix()
    ctx = SimpleNamespace(manifest=m, shared=SimpleNamespace(exposure={}, background_path=None))
    assert exposure(ctx)["right"] == pytest.approx(fitted.exposure["right"], abs=1e-5)
    ctx.shared.exposure = {"right": np.eye(3, 4)}  # this run's own fit
    assert exposure(ctx)["right"] is ctx.shared.exposure["right"]
    (tmp_path / "background.ply").write_bytes(b"")
    ctx = SimpleNamespace(manifest=m, shared=SimpleNamespace(exposure={}, background_path=tmp_path / "background.ply"))
    assert exposure(ctx) == {}  # splats without a record: every camera as rendered
    (tmp_path / "exposure.json").write_text('{"cameras": {"right": [[1, 0, 0], [0, 1, 0]]}}')
    with pytest.raises(InputError, match="cameras.right"):
        exposure(ctx)
    (tmp_path / "exposure.json").write_text('{"mode": "camera"}')
    with pytest.raises(InputError, match="exposure.json: cameras"):
        exposure(ctx)
