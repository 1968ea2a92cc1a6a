"""A rectified stereo rig's second camera becomes lateral ground truth of the first: the demo
street's recorded frames (left) and its Cycles truth 0.5 m to the right (right) written as a
COLMAP model, a nerfstudio dataset and a KITTI sequence come back as a one-camera package whose
``ground_truth.lateral`` holds the right images at the measured 0.5 m baseline, and the lateral
scorer gives them the scores the demo package gives its own truth. Pairs that are not rectified
are refused naming the file and the field."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from symdrive_core import conventions
from symdrive_core.cli import main
from symdrive_core.eval.views import evaluate_lateral
from symdrive_core.importers.similarity import apply_camera, transform_gaussians
from symdrive_core.io.images import read_image, write_image
from symdrive_core.io.ply import read_splats, write_splats
from symdrive_core.scene import check_files, load_manifest
from symdrive_core.scene.ground_truth import lateral_views, with_lateral_offsets

from .demo_formats import (
    CAMERA_HEIGHT,
    DEMO,
    demo_splats,
    demo_world,
    link_images,
    write_colmap,
    write_nerfstudio,
)
from .test_bad_input import assert_refused

pytest.importorskip("pycolmap")

BASELINE = 0.5  # the demo's lateral truth used as the rig's right camera, metres
SPLATS = None  # all of them: the lateral views see well past the road


def _truth_frames() -> tuple[list[int], dict[str, str]]:
    entry = next(e for e in load_manifest(DEMO).ground_truth["lateral"] if e["offset_m"] == BASELINE)
    return sorted(int(k) for k in entry["frames"]), entry["frames"]


@pytest.fixture(scope="module")
def rig():
    """The demo world's frames with truth at +0.5 m as a two-camera rig ``left``/``right``."""
    base = demo_world(seed=3, max_splats=SPLATS)
    frames, truth = _truth_frames()
    demo = load_manifest(DEMO)
    names = [f"{cam}/{fi:06d}.png" for cam in ("left", "right") for fi in frames]
    images = [base.images[fi] for fi in frames] + [demo.resolve(truth[str(fi)]) for fi in frames]
    c2w_demo = np.stack([base.c2w_demo[fi] for fi in frames]
                        + [conventions.lateral_shift(base.c2w_demo[fi], BASELINE) for fi in frames])
    return replace(base, names=names, images=images, c2w_demo=c2w_demo,
                   c2w=np.stack([apply_camera(base.S, c) for c in c2w_demo]))


def _import(args, out, capsys):
    rc = main(["import", *args, "--out", str(out), "--camera-height", str(CAMERA_HEIGHT), "--quiet"])
    printed = capsys.readouterr()
    assert rc == 0, printed.err
    return load_manifest(out, allow_external=True), printed.out


def _colmap_args(rig, root, lateral="right"):
    model = write_colmap(rig, root / "sparse")
    link_images(rig, root / "images")
    write_splats(root / "splat.ply", rig.splats)
    return ["colmap", str(model), "--images", str(root / "images"), "--splats", str(root / "splat.ply"),
            "--lateral-truth", lateral]


def _assert_truth_is_the_right_camera(m, root, n_frames, tol_m):
    """One camera; lateral truth at the baseline points at the right images, and each lateral
    view's camera is the right camera where the rig had it."""
    assert [c.name for c in m.cameras] == ["left"] and len(m.cameras[0].frames) == n_frames
    (entry,) = m.ground_truth["lateral"]
    assert entry["camera"] == "left" and entry["sensor"] == "right"  # recorded, not rendered
    assert abs(entry["offset_m"] - BASELINE) < tol_m, entry["offset_m"]
    assert m.effects.lateral_offsets == [entry["offset_m"]]
    frames, _ = _truth_frames()
    assert sorted(int(k) for k in entry["frames"]) == list(range(n_frames))
    for k, rel in entry["frames"].items():
        assert m.resolve(rel).samefile(root / "images" / "right" / f"{frames[int(k)]:06d}.png")
    views = lateral_views(m)
    assert len(views) == n_frames and {v.sensor for v in views} == {"right"}
    return views


def test_colmap_rig_right_camera_is_lateral_truth_at_the_baseline_and_scores_like_the_demo(rig, tmp_path, capsys):
    out = tmp_path / "pkg"
    m, printed = _import(_colmap_args(rig, tmp_path), out, capsys)
    assert "lateral ground truth: camera right, 15 images at +0.5" in printed
    check_files(m)
    views = _assert_truth_is_the_right_camera(m, tmp_path, 15, tol_m=2e-3)
    # the shifted left camera is the right camera of the rig, carried into the package's world
    T = np.asarray(m.source["transform"])
    for v, c2w_right in zip(views, rig.c2w[15:]):
        expected = apply_camera(T, c2w_right)
        assert np.linalg.norm(v.camera_to_world[:3, 3] - expected[:3, 3]) < 2e-3
        assert np.allclose(v.camera_to_world[:3, :3], expected[:3, :3], atol=1e-6)
    # the lateral scorer scores the real right images as it scores the demo's own truth
    frames = [0, 7, 14]
    imported = evaluate_lateral(m, read_splats(m.resolve(m.background_splats)), "raw_3dgs", frames)
    demo_frames = [_truth_frames()[0][i] for i in frames]
    native = evaluate_lateral(with_lateral_offsets(load_manifest(DEMO), [BASELINE]), demo_splats(SPLATS), "raw_3dgs",
                              demo_frames)
    print(f"lateral +0.5 m, frames {demo_frames}: imported rig PSNR {imported[0]['psnr']:.3f} dB, "
          f"SSIM {imported[0]['ssim']:.4f}; demo package PSNR {native[0]['psnr']:.3f} dB, SSIM {native[0]['ssim']:.4f}")
    assert imported[0]["frames"] == native[0]["frames"] == 3
    assert abs(imported[0]["psnr"] - native[0]["psnr"]) < 0.05
    assert abs(imported[0]["ssim"] - native[0]["ssim"]) < 2e-3
    assert imported[0]["psnr"] > 20.0  # the render really shows the street the right camera saw
    assert "lane_iou" in native[0] and "lane_iou" not in imported[0]  # no lane masks, no lane IoU


def test_nerfstudio_rig_right_camera_is_lateral_truth(rig, tmp_path, capsys):
    tj = write_nerfstudio(rig, tmp_path / "ns")
    m, _ = _import(["nerfstudio", str(tj), "--lateral-truth", "right"], tmp_path / "pkg", capsys)
    _assert_truth_is_the_right_camera(m, tmp_path / "ns", 15, tol_m=2e-3)


def _write_kitti(rig, root, *, P1=None, poses=None):
    """The rig as a KITTI odometry excerpt: image_0/image_1 named by demo frame number, calib.txt
    (pixel centres at integers), poses of camera 0 for every demo frame in frame 0's camera frame."""
    frames, _ = _truth_frames()
    K = rig.K.copy()
    K[:2, 2] -= 0.5
    P0 = np.hstack([K, np.zeros((3, 1))])
    if P1 is None:
        P1 = P0.copy()
        P1[0, 3] = -K[0, 0] * BASELINE
    for folder, offset in (("image_0", 0), ("image_1", 15)):
        for i, fi in enumerate(frames):
            dst = root / folder / f"{fi:06d}.png"
            dst.parent.mkdir(parents=True, exist_ok=True)
            dst.hardlink_to(rig.images[offset + i])
    lines = [" ".join(f"{x:.12e}" for x in P.ravel()) for P in (P0, P1)]
    (root / "calib.txt").write_text("".join(f"P{i}: {line}\n" for i, line in enumerate(lines)))
    if poses is None:
        demo = load_manifest(DEMO).cameras[0]
        first = np.linalg.inv(demo.frames[0].camera_to_world)
        poses = [first @ f.camera_to_world for f in demo.frames]
    (root / "poses.txt").write_text("".join(" ".join(f"{x:.12e}" for x in p[:3].ravel()) + "\n" for p in poses))
    return root


def test_kitti_excerpt_right_camera_is_lateral_truth_at_the_calibrated_baseline(rig, tmp_path, capsys):
    seq = _write_kitti(rig, tmp_path / "seq")
    out = tmp_path / "pkg"
    m, printed = _import(["kitti", str(seq), "--copy-images", "--camera-name", "left"], out, capsys)
    assert m.background_splats is None
    assert "at +0.5 m of camera left" in printed
    check_files(m)
    (entry,) = m.ground_truth["lateral"]
    assert entry["offset_m"] == BASELINE and entry["camera"] == "left"
    frames, _ = _truth_frames()
    assert m.source["frame_names"] == [f"{fi:06d}" for fi in frames]
    for k, rel in entry["frames"].items():
        assert np.array_equal(read_image(m.resolve(rel)), read_image(rig.images[15 + int(k)]))
    cam = m.cameras[0]
    assert np.allclose(cam.frames[0].K, rig.K, atol=1e-9)
    # relative poses are the demo's (the excerpt keeps every other frame), exact up to print precision
    demo = load_manifest(DEMO).cameras[0]
    for i, fi in enumerate(frames):
        got = np.linalg.inv(cam.frames[0].camera_to_world) @ cam.frames[i].camera_to_world
        expected = np.linalg.inv(demo.frames[0].camera_to_world) @ demo.frames[fi].camera_to_world
        assert np.allclose(got, expected, atol=1e-9)
    heights = [f.camera_to_world[2, 3] for f in cam.frames]
    # The ground: --camera-height below the cameras, on the plane the (level) path rides on, whatever
    # the camera's pitch.
    assert np.allclose(heights, CAMERA_HEIGHT, atol=1e-4)


def test_kitti_right_lens_differs_refused_naming_calib_and_P1(rig, tmp_path, capsys):
    P1 = np.hstack([rig.K * [[1.05], [1.05], [1]], [[-rig.K[0, 0] * BASELINE], [0], [0]]])
    seq = _write_kitti(rig, tmp_path / "seq", P1=P1)
    out = tmp_path / "pkg"
    rc = main(["import", "kitti", str(seq), "--out", str(out), "--camera-height", "1.6"])
    assert_refused(rc, capsys.readouterr().err.strip(), out, "calib.txt", "P1", "focal length", "not a rectified pair")


def test_kitti_right_camera_off_axis_refused(rig, tmp_path, capsys):
    P1 = np.hstack([rig.K, [[-rig.K[0, 0] * BASELINE], [-rig.K[1, 1] * 0.1], [0]]])  # 10 cm lower as well
    seq = _write_kitti(rig, tmp_path / "seq", P1=P1)
    out = tmp_path / "pkg"
    rc = main(["import", "kitti", str(seq), "--out", str(out), "--camera-height", "1.6"])
    assert_refused(rc, capsys.readouterr().err.strip(), out, "calib.txt", "P1", "not along its x axis")


def test_kitti_right_images_of_another_size_refused_naming_the_image(rig, tmp_path, capsys):
    seq = _write_kitti(rig, tmp_path / "seq")
    for p in (seq / "image_1").iterdir():
        p.unlink()
        write_image(p, np.zeros((rig.height, rig.width + 2, 3), np.float32))
    out = tmp_path / "pkg"
    rc = main(["import", "kitti", str(seq), "--out", str(out), "--camera-height", "1.6"])
    assert_refused(rc, capsys.readouterr().err.strip(), out, "image_1", "000000.png", f"{rig.width + 2}x{rig.height}")


def test_kitti_frame_without_a_pose_refused_naming_the_line(rig, tmp_path, capsys):
    demo = load_manifest(DEMO).cameras[0]
    seq = _write_kitti(rig, tmp_path / "seq", poses=[f.camera_to_world for f in demo.frames[:20]])
    out = tmp_path / "pkg"
    rc = main(["import", "kitti", str(seq), "--out", str(out), "--camera-height", "1.6"])
    assert_refused(rc, capsys.readouterr().err.strip(), out, "poses.txt", "line 21", "no pose for frame 20")


def test_colmap_rig_with_a_rotated_second_camera_refused(rig, tmp_path, capsys):
    turn = np.eye(4)
    a = np.radians(2.0)
    turn[:3, :3] = [[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]
    rotated = replace(rig, c2w=np.concatenate([rig.c2w[:15], rig.c2w[15:] @ turn]))
    out = tmp_path / "pkg"
    rc = main(["import", *_colmap_args(rotated, tmp_path), "--out", str(out), "--camera-height", "1.6"])
    assert_refused(rc, capsys.readouterr().err.strip(), out, "images.bin", "image_id 16 (right/000000.png)",
                   "rotated 2 degrees", "not a rectified pair")


def test_lateral_truth_naming_no_camera_refused(rig, tmp_path, capsys):
    out = tmp_path / "pkg"
    rc = main(["import", *_colmap_args(rig, tmp_path, lateral="rear"), "--out", str(out), "--camera-height", "1.6"])
    assert_refused(rc, capsys.readouterr().err.strip(), out, "--lateral-truth", "no camera 'rear'", "left, right")


def test_kitti_splats_in_the_poses_frame_score_like_the_demo(rig, tmp_path, capsys):
    """The demo's splats written in KITTI's frame (camera 0 at the first frame): the package's
    lateral views, K with pixel centres moved to +0.5 included, render as the demo's do."""
    seq = _write_kitti(rig, tmp_path / "seq")
    first = np.linalg.inv(load_manifest(DEMO).cameras[0].frames[0].camera_to_world)
    write_splats(tmp_path / "splat.ply", transform_gaussians(demo_splats(SPLATS), first))
    m, _ = _import(["kitti", str(seq), "--copy-images", "--splats", str(tmp_path / "splat.ply")], tmp_path / "pkg",
                   capsys)
    assert m.source["scale"] == 1.0
    frames = [0, 7]
    imported = evaluate_lateral(m, read_splats(m.resolve(m.background_splats)), "raw_3dgs", frames)
    native = evaluate_lateral(with_lateral_offsets(load_manifest(DEMO), [BASELINE]), demo_splats(SPLATS), "raw_3dgs",
                              [_truth_frames()[0][i] for i in frames])
    assert abs(imported[0]["psnr"] - native[0]["psnr"]) < 0.05, (imported, native)
    assert abs(imported[0]["ssim"] - native[0]["ssim"]) < 2e-3


def test_kitti_rig_trains_both_cameras_the_right_one_at_the_calibrated_baseline(rig, tmp_path, capsys):
    seq = _write_kitti(rig, tmp_path / "seq")
    m, printed = _import(["kitti", str(seq), "--copy-images", "--camera-name", "left", "--rig"], tmp_path / "pkg",
                         capsys)
    assert "both trained on" in printed and "lateral" not in (m.ground_truth or {})
    check_files(m)
    left, right = m.cameras
    assert (left.name, right.name) == ("left", "left_right")
    for a, b in zip(left.frames, right.frames):
        rel = np.linalg.inv(a.camera_to_world) @ b.camera_to_world
        assert np.allclose(rel[:3, :3], np.eye(3), atol=1e-9) and np.allclose(rel[:3, 3], [BASELINE, 0, 0], atol=1e-6)
        assert b.image is not None
