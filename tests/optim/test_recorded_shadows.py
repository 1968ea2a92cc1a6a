"""Recorded vehicles' shadows laid while fitting: the shading rule's gradient, when a scene lays
none, and a drive whose box casts a shadow: the fit learns the street lit, and removing the box
takes its shadow along."""

import dataclasses
import json
import shutil

import numpy as np
import pytest
import torch

from symdrive_core.eval.edits import evaluate_decomposition, evaluate_edits
from symdrive_core.optim.decompose import tracks
from symdrive_core.optim.reconstruct import ReconstructConfig, reconstruct
from symdrive_core.optim.recorded_shadows import RecordedShadows
from symdrive_core.scene import Effects, load_manifest
from symdrive_core.shadows.cast import shaded
from tests.optim.moving_box import traffic_truth_entries, write_moving_box

# Light travelling down and towards the recording camera: the box's shadow falls on the floor
# between them, where every frame sees it.
SUN = np.array([0.25, -0.6, -0.76]) / np.linalg.norm([0.25, -0.6, -0.76])


def test_shading_gradient_matches_finite_differences():
    rng = np.random.default_rng(0)
    bg = torch.tensor(rng.uniform(0.05, 0.95, (4, 5, 3)), dtype=torch.float64, requires_grad=True)
    occ = torch.tensor(rng.uniform(0.0, 1.0, (4, 5)), dtype=torch.float64)
    ratio = torch.tensor(0.4, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda b, r: shaded(b, occ, r), (bg, ratio))


def test_shading_is_identity_where_nothing_occludes_and_scales_linear_light_where_all_does():
    bg = torch.tensor([[[0.2, 0.5, 0.9]]], dtype=torch.float64)
    assert torch.equal(shaded(bg, torch.zeros(1, 1, dtype=torch.float64), 0.4), bg)
    full = shaded(bg, torch.ones(1, 1, dtype=torch.float64), 0.4)
    lin = lambda x: torch.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)  # noqa: E731
    assert torch.allclose(lin(full), 0.4 * lin(bg), atol=1e-12)


@pytest.mark.parametrize("effects", [Effects(), Effects(shadows=True), Effects(shadows=False, sun_direction=SUN),
                                     Effects(shadows=True, sun_direction=np.array([0.0, 0.6, 0.8]))])
def test_a_scene_without_a_casting_sun_lays_no_shadow(tmp_path, effects):
    root, *_ = write_moving_box(tmp_path / "pkg")
    m = dataclasses.replace(load_manifest(root), effects=effects)
    assert RecordedShadows.of(m, tracks(m), 0.05) is None


@pytest.fixture(scope="module")
def shadowed(tmp_path_factory):
    """The moving box casting its shadow, with removals of held-out frames 2 and 6 (the truth
    without the box and without its shadow); fitted twice: with the shadow laid (the scene's sun)
    and as a scene without shadows fits it (the darkening left to the background)."""
    root, box, truth, heldout = write_moving_box(tmp_path_factory.mktemp("shadowed") / "pkg", sun=SUN)
    m = load_manifest(root)
    vehicles, edits = traffic_truth_entries(root, truth)
    m.ground_truth = {**m.ground_truth, "edits": edits, "vehicles": vehicles}
    m.save()
    unlit = root.parent / "unlit"
    shutil.copytree(root, unlit)
    plain = load_manifest(unlit)
    plain.effects = Effects()
    plain.save()
    cfg = ReconstructConfig(iters=600, densify_from=100, densify_every=100, sky_points=0, actor_points=600,
                            checkpoint_every=10_000, sh_degree=0)
    laid = reconstruct(load_manifest(root), root / "laid", cfg, progress=False)
    baked = reconstruct(load_manifest(unlit), unlit / "baked", cfg, progress=False)
    return load_manifest(root), laid, load_manifest(unlit), baked, truth


def test_the_truth_has_a_shadow_outside_the_box(shadowed):
    *_, truth = shadowed
    for f in (2, 6):
        assert (truth[f]["shadow"] > 0.5).sum() > 20 and not (truth[f]["shadow"][truth[f]["mask"]] > 0.5).all()


def test_removing_a_box_fitted_with_its_shadow_takes_the_shadow_along(shadowed):
    m, laid, plain, baked, truth = shadowed
    assert set(laid.shadows) == {"car_1"} and baked.shadows == {}
    with_shadow = evaluate_edits(m, laid.gaussians, laid.actors, shadows=laid.shadows)["remove"]
    left_behind = evaluate_edits(plain, baked.gaussians, baked.actors)["remove"]
    assert with_shadow["psnr_car_and_shadow_dropped"] > left_behind["psnr_car_and_shadow_dropped"] + 2.0
    # and the recorded drive, shadow included, is rendered no worse than the fit that baked it in
    ours, theirs = evaluate_decomposition(m, laid.gaussians, laid.actors, shadows=laid.shadows), evaluate_decomposition(
        plain, baked.gaussians, baked.actors)
    assert ours["psnr_image"] > theirs["psnr_image"] - 0.5


def test_the_fitted_background_is_lit_where_the_shadow_fell(shadowed):
    m, laid, plain, baked, truth = shadowed
    from symdrive_core.eval.views import TrafficRenderer

    def street_error(result, manifest):
        errors = []
        for f in (2, 6):
            rgb, _ = TrafficRenderer(result.gaussians, {}).render(manifest, "front", f)
            region = truth[f]["shadow"] > 0.5
            errors.append(np.abs(rgb[region] - truth[f]["background"][region]).mean())
        return float(np.mean(errors))

    assert street_error(laid, m) < 0.5 * street_error(baked, plain)


def test_the_run_casts_the_shadows_of_recorded_vehicles_fitted_in_their_own_frames(shadowed):
    from symdrive_core.metrics import psnr
    from symdrive_core.pipeline.plan import make_plan
    from symdrive_core.pipeline.scene_render import SceneRenderer

    m, laid, plain, _, truth = shadowed
    stage = make_plan(m).stage("cast_shadow")
    assert stage.run and stage.actors == ["car_1"]  # the run's own fit decomposes the box
    assert not make_plan(plain).stage("cast_shadow").run
    renderer = SceneRenderer(m, background_gaussians=laid.gaussians, actor_gaussians=laid.actors,
                             actor_shadows=laid.shadows)
    for f in (2, 6):
        frame = renderer.render("front", f)
        cast = renderer.cast_shadows("front", f, frame, ["car_1"], m.effects.casting_sun()[0], m.effects.shade)
        assert cast.shadow is not None and (cast.shadow > 0.5).sum() > 20
        assert psnr(cast.rgb, truth[f]["rgb"]) > psnr(frame.rgb, truth[f]["rgb"]) + 2.0


def test_a_layer_starts_as_its_boxs_shadow_and_moves_with_the_vehicle():
    from symdrive_core.rotations import quat_from_yaw
    from symdrive_core.scene import Pose
    from symdrive_core.shadows.layer import INITIAL_SHADOW, ShadowLayer
    from symdrive_core.shadows.region import inside_convex, shadow_polygon

    wlh = np.array([1.8, 4.5, 1.5])
    start = Pose(np.array([3.0, -2.0, 0.75]), quat_from_yaw(0.4))
    layer = ShadowLayer.initial(wlh, SUN, start)
    # at its start pose the layer is the box's shadow hull in the world (to the grid's resolution)
    hull = shadow_polygon(start, wlh, SUN)
    rng = np.random.default_rng(0)
    pts = rng.uniform(hull.min(0) - 1.0, hull.max(0) + 1.0, (4000, 2))
    inside = inside_convex(pts, hull)
    occ = layer.at(start, wlh).sample(pts)
    far_in = inside_convex(pts, _shrunk(hull, 0.15))
    assert np.allclose(occ[far_in], INITIAL_SHADOW, atol=1e-6) and (occ[~inside] <= INITIAL_SHADOW + 1e-6).all()
    # moved and turned, the grid goes along: a point fixed in the vehicle's frame reads the same
    moved = Pose(np.array([-7.0, 5.0, 1.75]), quat_from_yaw(-1.1))
    local = np.column_stack([rng.uniform(-3, 3, 50), rng.uniform(-2, 2, 50), np.full(50, -0.75)])
    assert np.allclose(layer.at(start, wlh).sample(start.apply(local)[:, :2]),
                       layer.at(moved, wlh).sample(moved.apply(local)[:, :2]), atol=1e-9)
    assert layer.at(moved, wlh).ground_z == pytest.approx(1.0)


def _shrunk(hull: np.ndarray, margin: float) -> np.ndarray:
    """A convex polygon moved ``margin`` metres towards its centroid (inside it, for a test's
    points clear of the grid's cells on the edge)."""
    c = hull.mean(0)
    d = hull - c
    return c + d * (1.0 - margin / np.linalg.norm(d, axis=1, keepdims=True))


def test_a_layer_round_trips_and_a_bad_file_is_named(tmp_path):
    from symdrive_core.scene import Pose
    from symdrive_core.shadows.layer import ShadowLayer

    layer = ShadowLayer.initial(np.array([1.8, 4.5, 1.5]), SUN, Pose(np.zeros(3), np.array([1.0, 0, 0, 0])))
    layer.save(tmp_path / "a.shadow.safetensors")
    back = ShadowLayer.load(tmp_path / "a.shadow.safetensors")
    assert np.array_equal(back.occlusion, layer.occlusion) and np.allclose(back.origin, layer.origin)
    assert back.cell == layer.cell
    (tmp_path / "bad.safetensors").write_bytes(b"not a layer")
    with pytest.raises(ValueError, match="not a shadow layer file"):
        ShadowLayer.load(tmp_path / "bad.safetensors")


def test_a_package_names_a_vehicles_shadow_layer_and_checks_it(shadowed, tmp_path):
    from symdrive_core.scene import ManifestError, check_files

    m, laid, *_ = shadowed
    root = tmp_path / "pkg"
    shutil.copytree(m.root, root)
    pkg = load_manifest(root)
    pkg.actor("car_1").shadow = (laid.output / "actors" / "car_1.shadow.safetensors").relative_to(m.root).as_posix()
    pkg.save()
    back = load_manifest(root)
    assert back.actor("car_1").shadow == pkg.actor("car_1").shadow
    check_files(back)
    (root / back.actor("car_1").shadow).write_bytes(b"garbage")
    with pytest.raises(ManifestError, match=r"actors\[0\]\.assets\.shadow"):
        check_files(load_manifest(root))
    data = json.loads((root / "manifest.json").read_text())
    data["actors"][0]["kind"] = "inserted"
    (root / "manifest.json").write_text(json.dumps(data))
    with pytest.raises(ManifestError, match="only an existing actor has a learnt shadow layer"):
        load_manifest(root)


def test_the_layers_resume_from_the_checkpoint(shadowed, tmp_path):
    m, *_ = shadowed
    cfg = ReconstructConfig(iters=60, densify_from=100, sky_points=0, actor_points=300, checkpoint_every=30,
                            sh_degree=0)
    first = reconstruct(m, tmp_path / "fit", cfg, progress=False)
    back = RecordedShadows.of(m, tracks(m), cfg.shadow_lr)
    back.resume(tmp_path / "fit" / "checkpoint")
    learnt = back.layers["car_1"]
    assert np.allclose(learnt.layer().occlusion, first.shadows["car_1"].occlusion, atol=1e-7)
    assert int(back.opt.state[learnt.logits]["step"]) == 60
    second = reconstruct(m, tmp_path / "fit", dataclasses.replace(cfg, iters=80), resume=True, progress=False)
    assert second.metrics["resumed_from"] == 60 and not np.array_equal(second.shadows["car_1"].occlusion,
                                                                        first.shadows["car_1"].occlusion)
