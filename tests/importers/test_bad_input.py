"""Bad input exits 2 with one line naming the file and the field, and writes nothing."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from symdrive_core.cli import main

from .demo_formats import (
    CAMERA_HEIGHT,
    demo_world,
    link_images,
    write_colmap,
    write_gs_output,
    write_nerfstudio,
)

pytest.importorskip("pycolmap")


@pytest.fixture(scope="module")
def world():
    return demo_world(seed=11, max_splats=2000)


def run_import(args, out, capsys):
    rc = main(["import", *args, "--out", str(out), "--camera-height", str(CAMERA_HEIGHT)])
    err = capsys.readouterr().err.strip()
    return rc, err


def assert_refused(rc, err, out, *needles):
    assert rc == 2, err
    assert len(err.splitlines()) == 1, err
    for n in needles:
        assert n in err, (n, err)
    assert not out.exists()
    assert not [p for p in out.parent.iterdir() if p.name.startswith(f".{out.name}.")]


def colmap_args(world, root, **kw):
    model = write_colmap(world, root / "sparse", **kw)
    return ["colmap", str(model), "--images", str(root / "images")]


def test_missing_image(world, tmp_path, capsys):
    args = colmap_args(world, tmp_path)
    link_images(world, tmp_path / "images")
    (tmp_path / "images" / "000004.png").unlink()
    out = tmp_path / "pkg"
    assert_refused(*run_import(args, out, capsys), out, "000004.png", "image_id 5", "not found")


def test_image_size_not_the_cameras(world, tmp_path, capsys):
    from symdrive_core.io.images import write_image

    args = colmap_args(world, tmp_path)
    link_images(world, tmp_path / "images")
    (tmp_path / "images" / "000003.png").unlink()
    write_image(tmp_path / "images" / "000003.png", np.zeros((10, 12, 3), np.float32))
    out = tmp_path / "pkg"
    assert_refused(*run_import(args, out, capsys), out, "000003.png", "12x10", "image_id 4")


def test_distorted_camera_model_is_named(world, tmp_path, capsys):
    import pycolmap

    model = write_colmap(world, tmp_path / "sparse", binary=False)
    rec = pycolmap.Reconstruction(str(model))
    cam = rec.cameras[1]
    cam.model = pycolmap.CameraModelId.OPENCV
    cam.params = [world.K[0, 0], world.K[1, 1], world.K[0, 2], world.K[1, 2], -0.1, 0.01, 0.0, 0.0]
    rec.write_text(str(model))
    link_images(world, tmp_path / "images")
    out = tmp_path / "pkg"
    assert_refused(*run_import(["colmap", str(model), "--images", str(tmp_path / "images")], out, capsys), out,
                   "cameras.txt", "camera_id 1", "OPENCV")


def test_empty_model(world, tmp_path, capsys):
    import pycolmap

    model = tmp_path / "sparse"
    model.mkdir()
    pycolmap.Reconstruction().write_binary(str(model))
    out = tmp_path / "pkg"
    assert_refused(*run_import(["colmap", str(model), "--images", str(tmp_path)], out, capsys), out,
                   "images.bin", "no registered images")


def test_missing_model_files(tmp_path, capsys):
    out = tmp_path / "pkg"
    (tmp_path / "sparse").mkdir()
    assert_refused(*run_import(["colmap", str(tmp_path / "sparse"), "--images", str(tmp_path)], out, capsys), out,
                   "cameras.bin")


def _edit_ns(world, root, edit):
    tj = write_nerfstudio(world, root / "ns")
    data = json.loads(tj.read_text())
    edit(data)
    tj.write_text(json.dumps(data))
    return ["nerfstudio", str(tj)]


def test_nan_pose(world, tmp_path, capsys):
    def edit(d):
        d["frames"][3]["transform_matrix"][0][1] = float("nan")

    out = tmp_path / "pkg"
    assert_refused(*run_import(_edit_ns(world, tmp_path, edit), out, capsys), out, "transforms.json",
                   "frames[3].transform_matrix", "not finite")


def test_duplicate_image_name(world, tmp_path, capsys):
    def edit(d):
        d["frames"][5]["file_path"] = d["frames"][2]["file_path"]

    out = tmp_path / "pkg"
    assert_refused(*run_import(_edit_ns(world, tmp_path, edit), out, capsys), out, "transforms.json",
                   "frames[5]", "duplicate image name")


def test_unknown_camera_model(world, tmp_path, capsys):
    def edit(d):
        d["camera_model"] = "EQUIRECTANGULAR"

    out = tmp_path / "pkg"
    assert_refused(*run_import(_edit_ns(world, tmp_path, edit), out, capsys), out, "transforms.json",
                   "camera_model", "EQUIRECTANGULAR")


def test_nan_pose_in_3dgs_cameras(world, tmp_path, capsys):
    model = write_gs_output(world, tmp_path / "run", tmp_path / "data" / "images")
    cams = json.loads((model / "cameras.json").read_text())
    cams[1]["position"][2] = float("nan")
    (model / "cameras.json").write_text(json.dumps(cams))
    out = tmp_path / "pkg"
    assert_refused(*run_import(["3dgs", str(model)], out, capsys), out, "cameras.json", "[1].position")


def test_no_ground_says_how_to_pass_up(world, tmp_path, capsys):
    from symdrive_core.io.points import write_points

    model = write_gs_output(world, tmp_path / "run", tmp_path / "data" / "images")
    cams = json.loads((model / "cameras.json").read_text())
    up = -np.asarray(cams[0]["rotation"])[:, 1]
    above = np.array([c["position"] for c in cams]) + 5.0 * up
    write_points(model / "input.ply", above, np.full((len(above), 3), 0.5))
    out = tmp_path / "pkg"
    rc, err = run_import(["3dgs", str(model)], out, capsys)
    assert_refused(rc, err, out, "--up")


def test_an_existing_folder_is_replaced_only_when_a_package_and_asked(world, tmp_path, capsys):
    args = colmap_args(world, tmp_path)
    link_images(world, tmp_path / "images")
    out = tmp_path / "pkg"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    rc, err = run_import(args, out, capsys)
    assert rc == 2 and "not a scene package" in err and (out / "keep.txt").read_text() == "mine"
    rc, err = run_import([*args, "--force"], out, capsys)  # somebody's folder: --force does not replace it
    assert rc == 2 and (out / "keep.txt").read_text() == "mine"
    (out / "keep.txt").unlink()
    assert run_import(args, out, capsys)[0] == 0  # an empty folder is fine
    rc, err = run_import(args, out, capsys)
    assert rc == 2 and "--force" in err and (out / "manifest.json").is_file()
    assert run_import([*args, "--force"], out, capsys)[0] == 0  # a package is replaced when asked


# ---------------------------------------------------------------- names that lead out, odd files


@pytest.mark.parametrize("name", ["../outside.png", "/etc/hostname", "sub/../../outside.png"])
def test_a_colmap_image_name_leading_out_of_the_images_is_refused_not_read(world, tmp_path, capsys, name):
    link_images(world, tmp_path / "m" / "images")
    (tmp_path / "outside.png").write_bytes((tmp_path / "m" / "images" / "000000.png").read_bytes())
    args = colmap_args(replace(world, names=[name, *world.names[1:]]), tmp_path / "m")
    out = tmp_path / "pkg"
    assert_refused(*run_import(args, out, capsys), out, "images.bin", "image_id 1", repr(name), "lies outside")


@pytest.mark.parametrize("key, value, field", [
    ("file_path", "../outside.png", "frames[0].file_path"),
    ("file_path", "/etc/hostname", "frames[0].file_path"),
    ("file_path", "images/a/../../../outside.png", "frames[0].file_path"),
    ("ply_file_path", "/etc/passwd", "ply_file_path"),
    ("ply_file_path", "../../outside.ply", "ply_file_path"),
])
def test_a_nerfstudio_path_leading_out_of_its_folder_is_refused_not_read(world, tmp_path, capsys, key, value, field):
    def edit(d):
        (d["frames"][0] if key == "file_path" else d)[key] = value

    out = tmp_path / "pkg"
    assert_refused(*run_import(_edit_ns(world, tmp_path, edit), out, capsys), out, "transforms.json", f": {field}: ",
                   repr(value), "lies outside")


def _gs_model(world, root, edit=None, cfg=None):
    model = write_gs_output(world, root / "run", root / "data" / "images")
    cams = json.loads((model / "cameras.json").read_text())
    if edit is not None:
        edit(cams)
        (model / "cameras.json").write_text(json.dumps(cams))
    if cfg is not None:
        (model / "cfg_args").write_text(cfg)
    return model


@pytest.mark.parametrize("name", ["../../outside", "/etc/hostname"])
def test_a_3dgs_img_name_leading_out_of_the_images_is_refused_not_read(world, tmp_path, capsys, name):
    model = _gs_model(world, tmp_path, lambda cams: cams[0].update(img_name=name))
    (tmp_path / "outside.png").write_bytes((tmp_path / "data" / "images" / "000001.png").read_bytes())
    out = tmp_path / "pkg"
    assert_refused(*run_import(["3dgs", str(model), "--images", str(tmp_path / "data" / "images")], out, capsys),
                   out, "cameras.json", "[0].img_name", "lies outside")


def test_json_nested_past_the_parser_is_refused(world, tmp_path, capsys):
    tj = write_nerfstudio(world, tmp_path / "ns")
    tj.write_text("[" * 100_000 + "]" * 100_000)
    model = _gs_model(world, tmp_path)
    (model / "cameras.json").write_text('{"a": [' + "1" * 5000 + "]}")  # a number past int()'s digits
    for args, file in ((["nerfstudio", str(tj)], "transforms.json"), (["3dgs", str(model)], "cameras.json")):
        out = tmp_path / f"pkg_{file}"
        assert_refused(*run_import(args, out, capsys), out, file, "not valid JSON")


def test_3dgs_size_past_float_range_and_cfg_args_without_paths_are_refused(world, tmp_path, capsys):
    model = _gs_model(world, tmp_path / "a")
    (model / "cameras.json").write_text((model / "cameras.json").read_text().replace('"width": ', '"width": 1e400, "w": ', 1))
    out = tmp_path / "pkg"
    assert_refused(*run_import(["3dgs", str(model), "--images", str(tmp_path / "a" / "data" / "images")], out, capsys),
                   out, "cameras.json", "[0]")
    model = _gs_model(world, tmp_path / "b", cfg="Namespace(source_path=5, images='images')")
    assert_refused(*run_import(["3dgs", str(model)], out, capsys), out, "cfg_args", ": source_path: ", "got 5")
    model = _gs_model(world, tmp_path / "c", cfg="Namespace(source_path='/data', images=None)")
    assert_refused(*run_import(["3dgs", str(model)], out, capsys), out, "cfg_args", ": images: ", "got None")


def test_cfg_args_is_not_read_when_images_are_given(world, tmp_path, capsys):
    model = _gs_model(world, tmp_path, cfg="not a Namespace (((")
    rc, err = run_import(["3dgs", str(model), "--images", str(tmp_path / "data" / "images")], tmp_path / "pkg", capsys)
    assert rc == 0, err


def test_a_truncated_png_is_refused_naming_it(world, tmp_path, capsys):
    args = colmap_args(world, tmp_path)
    link_images(world, tmp_path / "images")
    png = tmp_path / "images" / "000002.png"
    data = png.read_bytes()
    png.unlink()
    png.write_bytes(data[: len(data) // 2])  # the header reads, the pixels run out
    out = tmp_path / "pkg"
    assert_refused(*run_import(args, out, capsys), out, "000002.png", "image_id 3", "truncated")


def test_a_value_no_package_may_hold_is_named_by_the_input_not_the_temporary_package(world, tmp_path, capsys):
    def edit(d):
        d["cx"] = 1e12

    out = tmp_path / "pkg"
    rc, err = run_import([*_edit_ns(world, tmp_path, edit), "--quiet"], out, capsys)  # no progress bar
    assert_refused(rc, err, out, "transforms.json: ", ".K: ", "in the scene package made from this input")
    assert ".part" not in err and "manifest.json" not in err
