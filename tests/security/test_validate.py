"""``symdrive validate`` reads the header and size of every file it names, without loading data:
broken PLYs, images whose size is not the camera's and unrecognisable meshes are refused with
one line naming the manifest, the field and the file."""

from __future__ import annotations

import json
import time
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.io.images import write_image
from symdrive_core.scene import check_files, load_manifest
from symdrive_core.scene.manifest import SCHEMA_PATH

DEMO = Path(__file__).resolve().parents[2] / "symdrive_core" / "data" / "demo_street"


def _validate(manifest, capsys) -> tuple[int, str]:
    code = main(["validate", str(manifest)])
    captured = capsys.readouterr()
    return code, captured.err


def _package_with_images(make_package, size=(32, 24)) -> Path:
    """The tiny package with a ground-truth PNG and depth EXR per frame, a mesh and a mask."""
    manifest = make_package()
    root = manifest.parent
    d = json.loads(manifest.read_text())
    for i, cf in enumerate(d["cameras"][0]["frames"]):
        write_image(root / f"img{i}.png", np.zeros((size[1], size[0], 3), np.float32))
        write_image(root / f"depth{i}.exr", np.ones((size[1], size[0]), np.float32))
        cf["image"], cf["depth"] = f"img{i}.png", f"depth{i}.exr"
    (root / "car.obj").write_text("# a triangle\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    d["actors"][0]["assets"]["mesh"] = "car.obj"
    write_image(root / "mask0.png", np.zeros((size[1], size[0]), np.float32))
    d["masks"] = {"entries": [{"camera": "front", "frame": 0, "actor": "car_0", "visible": "mask0.png"}]}
    manifest.write_text(json.dumps(d))
    return manifest


def test_a_good_package_validates(make_package, capsys):
    manifest = _package_with_images(make_package)
    assert _validate(manifest, capsys) == (0, "")


def _ply_header(n=10, props=("x", "y", "z")) -> bytes:
    return ("ply\nformat binary_little_endian 1.0\n" f"element vertex {n}\n"
            + "".join(f"property float {p}\n" for p in props) + "end_header\n").encode()


def _truncated(path: Path) -> None:
    path.write_bytes(path.read_bytes()[:-300])


def _empty(path: Path) -> None:
    path.write_bytes(b"")


def _random(path: Path) -> None:
    path.write_bytes(np.random.default_rng(0).integers(0, 256, 4000, dtype=np.uint8).tobytes())


def _duplicate_property(path: Path) -> None:
    path.write_bytes(_ply_header(1, ("x", "y", "z", "x")) + bytes(16))


def _negative_count(path: Path) -> None:
    path.write_bytes(_ply_header(-5) + bytes(64))


def _no_splat_properties(path: Path) -> None:
    path.write_bytes(_ply_header(2) + bytes(24))


@pytest.mark.parametrize("target,field", [("car_0.ply", r"actors[0].assets.splats"),
                                          ("background.ply", "background.splats")])
@pytest.mark.parametrize("damage,message", [
    (_truncated, "truncated: header declares 50 vertices"),
    (_empty, "not a PLY file"),
    (_random, "not a PLY file"),
    (_duplicate_property, "duplicate property 'x'"),
    (_negative_count, "negative count -5"),
    (_no_splat_properties, "not a 3DGS splat file"),
])
def test_validate_reads_every_ply_header(make_package, capsys, target, field, damage, message):
    manifest = make_package()
    if target == "background.ply":
        message = message.replace("50 vertices", "200 vertices")
    damage(manifest.parent / target)
    code, err = _validate(manifest, capsys)
    assert code == 2, err
    assert err.count("\n") == 1, err
    assert str(manifest) in err and f"{field}: {target}" in err and message in err, err


@pytest.mark.parametrize("which,field", [("img1.png", r"cameras[0].frames[1].image"),
                                         ("depth2.exr", r"cameras[0].frames[2].depth"),
                                         ("mask0.png", r"masks.entries[0].visible")])
def test_validate_checks_image_size_against_the_camera(make_package, capsys, which, field):
    manifest = _package_with_images(make_package)
    channels = 1 if which != "img1.png" else 3
    write_image(manifest.parent / which, np.zeros((24, 40, channels), np.float32))
    code, err = _validate(manifest, capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert f"{field}: {which}: image is 40x24, the camera is 32x24" in err, err


def test_validate_refuses_an_image_that_is_not_one(make_package, capsys):
    manifest = _package_with_images(make_package)
    _random(manifest.parent / "img0.png")
    code, err = _validate(manifest, capsys)
    assert code == 2 and "cameras[0].frames[0].image: img0.png: cannot read image" in err, err


@pytest.mark.parametrize("content", [b"", b"\x00\x01binary junk\xff" * 50])
def test_validate_refuses_a_mesh_that_is_not_one(make_package, capsys, content):
    manifest = _package_with_images(make_package)
    (manifest.parent / "car.obj").write_bytes(content)
    code, err = _validate(manifest, capsys)
    assert code == 2 and "actors[0].assets.mesh: car.obj: mesh:" in err, err


def test_check_files_without_headers_only_checks_existence(make_package):
    manifest = make_package()
    _random(manifest.parent / "car_0.ply")
    check_files(load_manifest(manifest), headers=False)


def test_validate_on_the_demo_is_fast():
    m = load_manifest(DEMO)
    t0 = time.perf_counter()
    check_files(m)
    assert time.perf_counter() - t0 < 5.0


@pytest.mark.parametrize("value,ok", [("front", True), ("Camera.001", True), ("car 1", True), ("é", True),
                                      ("a/b", False), ("a\\b", False), ("..", False), ("x..y", False),
                                      (".hidden", False), ("a\x00b", False), ("a\nb", False), ("", False),
                                      ("x" * 128, True), ("x" * 129, False)])
def test_schema_and_loader_agree_on_names(make_package, value, ok):
    from symdrive_core.errors import InputError
    from symdrive_core.scene import check_name

    schema = json.loads(SCHEMA_PATH.read_text())
    d = json.loads(make_package().read_text())
    d["cameras"][0]["name"] = value
    if ok:
        jsonschema.validate(d, schema)
        assert check_name(value, "name") == value
    else:
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(d, schema)
        with pytest.raises(InputError):
            check_name(value, "name")


@pytest.mark.parametrize("value,ok", [("output", True), ("runs/a", True), ("./out", True),
                                      ("/abs", False), ("\\abs", False), ("C:\\x", False), ("..", False),
                                      ("../out", False), ("a/../b", False), (".", False), ("a\x00", False)])
def test_schema_and_loader_agree_on_output(make_package, value, ok):
    from symdrive_core.scene import ManifestError, parse_manifest

    schema = json.loads(SCHEMA_PATH.read_text())
    manifest = make_package()
    d = json.loads(manifest.read_text())
    d["output"] = value
    if ok:
        jsonschema.validate(d, schema)
        assert parse_manifest(d, manifest).output == value
    else:
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(d, schema)
        with pytest.raises(ManifestError, match="manifest.json: output: "):
            parse_manifest(d, manifest)
