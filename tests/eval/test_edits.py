"""Scoring moving traffic: a decomposed reconstruction against a static one on the moving
vehicles' pixels, and edits of a recorded vehicle against their truth, on the moving-box drive
(truth rendered from its true Gaussians)."""

import json
import shutil

import numpy as np
import pytest
import torch

from symdrive_core.eval.edits import evaluate_decomposition, evaluate_edits
from symdrive_core.io.images import write_image, write_mask
from symdrive_core.optim.reconstruct import ReconstructConfig, reconstruct
from symdrive_core.scene import Pose, load_manifest
from symdrive_core.scene.camera import CameraView
from symdrive_core.scene.ground_truth import split_frames
from symdrive_core.splat.render import render_scene
from symdrive_core.splat.tensors import GaussianTensors
from tests.optim.moving_box import box_pose, street, traffic_truth_entries

MOVE = np.array([0.0, -1.5, 0.0])  # a lane nearer the camera


@pytest.fixture(scope="module")
def traffic_truth(moving_box, tmp_path_factory):
    """The moving box with ``ground_truth.vehicles`` and three edits of held-out frames: remove at
    frames 2 and 6, move at frame 6."""
    src, result, truth, box, heldout = moving_box
    root = tmp_path_factory.mktemp("traffic") / "pkg"
    shutil.copytree(src, root)
    m = load_manifest(root)
    vehicles, edits = traffic_truth_entries(root, truth)
    moved = Pose(box_pose(6).translation + MOVE, box_pose(6).rotation)
    with torch.no_grad():
        out = render_scene(GaussianTensors.from_gaussians(street()), [(GaussianTensors.from_gaussians(box), moved, 1)],
                           CameraView.of_frame(m.cameras[0], 6))
    write_image(root / "gt/edits/2/image.png", out["rgb"].clamp(0, 1).numpy())
    write_mask(root / "gt/edits/2/mask.png", out["instance"][..., 0].numpy() > 0.5)
    edits.append({"kind": "move", "actor": "car_1", "camera": "front", "frame": 6, "pose": moved.to_json(),
                  "lateral_m": -1.5, "image": "gt/edits/2/image.png", "mask": "gt/edits/2/mask.png"})
    m.ground_truth = {**m.ground_truth, "vehicles": vehicles, "edits": edits}
    m.save()
    return load_manifest(root), result


def test_decomposed_beats_static_on_the_vehicles_pixels(traffic_truth, tmp_path):
    m, decomposed = traffic_truth
    cfg = ReconstructConfig(iters=600, densify_from=100, densify_every=100, sky_points=0, checkpoint_every=10_000,
                            sh_degree=0, decompose=False)
    static = reconstruct(m, tmp_path / "static", cfg, progress=False)
    d = evaluate_decomposition(m, decomposed.gaussians, decomposed.actors)
    s = evaluate_decomposition(m, static.gaussians, {})
    assert d["frames"] == s["frames"] == 4
    assert d["psnr_vehicles"] > s["psnr_vehicles"] + 3.0 and d["psnr_elsewhere"] > s["psnr_elsewhere"] - 0.5


def test_another_camera_is_scored_only_with_its_own_masks(traffic_truth):
    """The truth's vehicle masks are the first camera's: a second camera named without masks of its
    own is refused, not scored against them; named with them it is scored as the first camera is."""
    from dataclasses import replace

    m, decomposed = traffic_truth
    first = m.cameras[0]
    rig = replace(m, cameras=[first, replace(first, name="side")])
    with pytest.raises(ValueError, match="side"):
        evaluate_decomposition(rig, decomposed.gaussians, decomposed.actors, camera="side")
    whole = {f: np.ones((first.height, first.width), bool) for f in range(len(m.frames))}
    side = evaluate_decomposition(rig, decomposed.gaussians, decomposed.actors, masks=whole, camera="side")
    assert side["frames"] == 4 and side == evaluate_decomposition(m, decomposed.gaussians, decomposed.actors,
                                                                  masks=whole)


def test_edits_are_scored_with_and_without_inpainting(traffic_truth):
    m, decomposed = traffic_truth
    calls = []

    def grey(image, region):  # an inpainter that paints the region grey
        calls.append(int(region.sum()))
        out = image.copy()
        out[region] = 0.5
        return out

    rows = evaluate_edits(m, decomposed.gaussians, decomposed.actors, inpaint=grey)
    assert rows["remove"]["edits"] == 2 and rows["move"]["edits"] == 1
    assert rows["remove"]["psnr_exposed_dropped"] > 15.0  # the street behind the box was seen
    assert 0.0 < rows["remove"]["unseen_fraction"] < 0.5  # frame 2: some of it no frame saw
    assert len(calls) >= 1 and rows["remove"]["psnr_exposed_inpainted"] != rows["remove"]["psnr_exposed_dropped"]
    assert rows["move"]["psnr_car"] > 15.0 and rows["move"]["car_silhouette_iou"] > 0.7
    plain = evaluate_edits(m, decomposed.gaussians, decomposed.actors)
    assert "psnr_exposed_inpainted" not in plain["remove"]


def test_the_traffic_script_writes_its_table_and_figure(traffic_truth, tmp_path):
    from symdrive_core.io.images import read_image
    from tests.scripts import load_script

    m, _ = traffic_truth
    rec = m.root / "reconstruction"
    out, figure = tmp_path / "traffic.json", tmp_path / "figure.png"
    assert load_script("eval_traffic").main([str(m.root), "--static", str(rec), "--decomposed", str(rec),
                                              "--no-inpaint", "--out", str(out), "--figure", str(figure)]) == 0
    result = json.loads(out.read_text())
    assert result["heldout"]["decomposed"]["frames"] == 4 and set(result["edits"]) == {"remove", "move"}
    assert read_image(figure, channels=3).shape == (m.cameras[0].height, 5 * m.cameras[0].width + 16, 3)


def test_a_real_drives_label_boxes_score_its_moving_vehicles(traffic_truth, tmp_path):
    """``eval_tracked_drive.py``: the labels' 2D boxes (drawn on images twice the package's size)
    become the moving vehicles' pixels, the bounding rectangles of the truth's masks, and each fit is
    scored over them as :func:`evaluate_decomposition` scores with those masks."""
    from symdrive_core.io.images import read_mask
    from tests.scripts import load_script

    m, decomposed = traffic_truth
    truth = {int(f): read_mask(m.resolve(p)) > 0.5 for f, p in m.ground_truth["vehicles"]["frames"].items()}
    lines, rects = [], {}
    for f, mask in truth.items():
        if not mask.any():
            continue
        ys, xs = np.nonzero(mask)
        rects[f] = np.zeros_like(mask)
        rects[f][ys.min():ys.max() + 1, xs.min():xs.max() + 1] = True
        # KITTI's pixels at twice the size: package pixel j covers label pixels 2j and 2j + 1
        lines.append(f"{f} 1 Car 0 0 0 {2 * xs.min()} {2 * ys.min()} {2 * xs.max() + 1} {2 * ys.max() + 1} 1 1 1 0 0 0 0")
    lines.append(f"{min(rects)} 7 Car 0 0 0 0 0 5 5 1 1 1 0 0 0 0")  # a vehicle that is no actor of the package
    labels = tmp_path / "0001.txt"
    labels.write_text("\n".join(lines) + "\n")
    script = load_script("eval_tracked_drive")
    assert script.moving_tracks(m, 2.0) == ["car_1"]
    shape, size = (m.cameras[0].height, m.cameras[0].width), (2 * m.cameras[0].width, 2 * m.cameras[0].height)
    masks = script.label_masks(labels, ["track_1"], shape, size)
    assert set(masks) == set(rects) and all(np.array_equal(masks[f], rects[f]) for f in rects)
    # the script names tracks as ``import tracks`` does: the box as actor ``track_1``
    root = tmp_path / "pkg"
    shutil.copytree(m.root, root)
    (root / "manifest.json").write_text((root / "manifest.json").read_text().replace('"car_1"', '"track_1"'))
    for path in (root / "reconstruction/actors").glob("car_1.*"):
        path.rename(path.with_name(path.name.replace("car_1", "track_1")))
    out = tmp_path / "tracked.json"
    assert script.main([str(root), str(labels), "--fit", f"decomposed={root / 'reconstruction'}",
                        "--label-size", *map(str, size), "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["moving"] == ["track_1"]
    scored = result["decomposed"]
    assert scored["label_boxes"] == evaluate_decomposition(m, decomposed.gaussians, decomposed.actors, masks=rects)
    assert scored["label_boxes"]["psnr_vehicles"] != evaluate_decomposition(m, decomposed.gaussians,
                                                                           decomposed.actors)["psnr_vehicles"]
    boxes = script.projected_box_masks(load_manifest(root), ["track_1"], m.cameras[0].name)
    assert scored["boxes"] == {m.cameras[0].name: evaluate_decomposition(m, decomposed.gaussians, decomposed.actors,
                                                                         masks=boxes)}
    assert scored["boxes_pooled"] == scored["boxes"][m.cameras[0].name]  # one camera: pooled is its score
    # the frames the fit learnt from, on request
    assert script.main([str(root), str(labels), "--fit", f"decomposed={root / 'reconstruction'}",
                        "--label-size", *map(str, size), "--out", str(out), "--training-frames"]) == 0
    train = [f for f in split_frames(m)[0] if f in rects]
    trained = json.loads(out.read_text())["decomposed"]["label_boxes"]
    assert train and trained == evaluate_decomposition(m, decomposed.gaussians, decomposed.actors, train, masks=rects)
    assert trained["frames"] == len(train) != scored["label_boxes"]["frames"]


def test_projected_boxes_hold_the_vehicles_surface(traffic_truth):
    """The 3D box at its recorded pose, projected: its bounding rectangle holds exactly the pixels
    whose centres lie within the extremes of the true box's surface points (its Gaussians' centres,
    the corners among them) placed by the true pose and projected: the actor's pose, the box's axes
    and the pixel centres agree."""
    from symdrive_core import conventions
    from tests.optim.moving_box import true_box
    from tests.scripts import load_script

    m, _ = traffic_truth
    cam = m.cameras[0]
    boxes = load_script("eval_tracked_drive").projected_box_masks(m, ["car_1"], cam.name)
    surface = true_box().means
    assert len(boxes) >= 10
    for f, mask in boxes.items():
        uv, z = conventions.project_points(box_pose(f).apply(surface), cam.frames[f].world_to_camera, cam.frames[f].K)
        (x0, y0), (x1, y1) = np.ceil(uv.min(0)).astype(int), np.floor(uv.max(0)).astype(int)
        rect = np.zeros_like(mask)
        rect[max(y0, 0):y1 + 1, max(x0, 0):x1 + 1] = True
        assert (z > 0).all() and np.array_equal(rect, mask), f
