"""Every bad input exits 2 with one line naming the file and the field, never a traceback:
broken PLY headers, absurd numbers, deep JSON, huge images, names that are paths."""

from __future__ import annotations

import json
import os
import re
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from symdrive_core.cli import main
from symdrive_core.errors import InputError
from symdrive_core.io.images import read_image, write_image
from symdrive_core.scene import load_manifest
from symdrive_core.scene.manifest import SCHEMA_PATH


def _cli(capsys, *args) -> tuple[int, str]:
    code = main([str(a) for a in args])
    return code, capsys.readouterr().err


def _one_line_naming(code: int, err: str, *names: str) -> None:
    assert code == 2, err
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert "Traceback" not in err, err
    for name in names:
        assert name in err, (name, err)


def _ply(path: Path, header_lines: list[str], data: bytes = b"") -> Path:
    path.write_bytes(("\n".join(["ply", "format binary_little_endian 1.0", *header_lines, "end_header"]) + "\n").encode()
                     + data)
    return path


# ------------------------------------------------------------------ PLY files


def test_duplicate_ply_property(tmp_path, capsys):
    path = _ply(tmp_path / "dup.ply", ["element vertex 1", "property float x", "property float x"], bytes(8))
    _one_line_naming(*_cli(capsys, "info", path), str(path), "element vertex", "duplicate property 'x'")


def test_negative_vertex_count(tmp_path, capsys):
    path = _ply(tmp_path / "neg.ply", ["element vertex -3", "property float x"], bytes(8))
    _one_line_naming(*_cli(capsys, "info", path), str(path), "element vertex", "negative count -3")


def test_vertex_count_with_thousands_of_digits(tmp_path, capsys):
    path = _ply(tmp_path / "digits.ply", ["element vertex " + "9" * 5000, "property float x"])
    _one_line_naming(*_cli(capsys, "info", path), str(path), "header", "bad element line")


def test_element_with_no_properties(tmp_path, capsys):
    path = _ply(tmp_path / "empty_el.ply", ["element vertex 1000000000000"])
    _one_line_naming(*_cli(capsys, "info", path), str(path), "element vertex", "no properties")


def test_compressed_ply_with_float_packed_words(tmp_path, capsys):
    lines = ["element chunk 1", *[f"property float {b}" for b in ("min_x", "min_y", "min_z", "max_x", "max_y",
                                                                    "max_z", "min_scale_x", "min_scale_y",
                                                                    "min_scale_z", "max_scale_x", "max_scale_y",
                                                                    "max_scale_z")],
             "element vertex 1", *[f"property float packed_{p}" for p in ("position", "rotation", "scale", "color")]]
    path = _ply(tmp_path / "c.compressed.ply", lines, bytes(12 * 4 + 16))
    _one_line_naming(*_cli(capsys, "info", path), str(path), "element vertex", "must be uint32")


# ------------------------------------------------------------------ manifests


def _package(make_package, mutate) -> Path:
    manifest = make_package()
    d = json.loads(manifest.read_text())
    mutate(d)
    manifest.write_text(json.dumps(d))
    return manifest


def _set(path, value):
    def mutate(d):
        *parents, last = path
        node = d
        for p in parents:
            node = node[p]
        node[last] = value
    return mutate


BAD_MANIFESTS = [
    ("fx 1e-300", _set(["cameras", 0, "frames", 0, "K", 0, 0], 1e-300), "cameras[0].frames[0].K", "fx, fy must lie"),
    ("fy huge", _set(["cameras", 0, "frames", 1, "K", 1, 1], 1e200), "cameras[0].frames[1].K", "fx, fy must lie"),
    ("width 100000", _set(["cameras", 0, "width"], 100000), "cameras[0].width", "<= 16384"),
    ("height 100000", _set(["cameras", 0, "height"], 100000), "cameras[0].height", "<= 16384"),
    ("wlh 1e300", _set(["actors", 0, "wlh"], [1.8, 1e300, 1.5]), "actors[0].wlh[1]", "<= 1000"),
    ("translation 1e300", _set(["actors", 0, "poses", 0, "translation"], [1e300, 0, 0]),
     "actors[0].poses[0].translation", "beyond"),
    ("translation 10**400", _set(["actors", 0, "poses", 0, "translation"], [10 ** 400, 0, 0]),
     "actors[0].poses[0].translation", "finite"),
    ("lateral offset 1e300", _set(["effects", "lateral_offsets"], [1e300]), "effects.lateral_offsets[0]", "<= 1000"),
    ("instance id 10**30", _set(["actors", 0, "instance_id"], 10 ** 30), "actors[0].instance_id", "<= 65535"),
    ("NUL in an actor id", _set(["actors", 0, "id"], "car\x00"), "actors[0].id", "control characters"),
    ("NUL in a camera name", _set(["cameras", 0, "name"], "fr\x00nt"), "cameras[0].name", "control characters"),
    ("newline in the scene name", _set(["name"], "a\nb"), "name", "control characters"),
    ("absolute camera name", _set(["cameras", 0, "name"], "/elsewhere/CAM"), "cameras[0].name", "'/'"),
    ("climbing camera name", _set(["cameras", 0, "name"], "../../CAM"), "cameras[0].name", "'/'"),
    ("climbing actor id", _set(["actors", 0, "id"], "../../../A"), "actors[0].id", "'/'"),
    ("backslash actor id", _set(["actors", 0, "id"], "..\\..\\A"), "actors[0].id", "'\\'"),
    ("dot-dot actor id", _set(["actors", 0, "id"], ".."), "actors[0].id", "'..'"),
    ("hidden scene name", _set(["name"], ".git"), "name", "start with '.'"),
    ("long scene name", _set(["name"], "x" * 129), "name", "at most 128"),
    ("absolute output", _set(["output"], "/some/dir"), "output", "relative path"),
    ("climbing output", _set(["output"], "../../out"), "output", "inside the package"),
    ("NUL in an asset path", _set(["actors", 0, "assets", "splats"], "car\x00.ply"), "actors[0].assets.splats",
     "control characters"),
    ("unicode digit id-map key", _set(["masks"], {"id_maps": [{"camera": "front", "frame": 0, "path": "x.png",
                                                                "ids": {"\u00b2": "car_0"}}]}),
     "masks.id_maps[0].ids", "positive integer"),
]


@pytest.mark.parametrize("label,mutate,field,message", BAD_MANIFESTS, ids=[b[0] for b in BAD_MANIFESTS])
@pytest.mark.parametrize("command", ["validate", "plan"])
def test_bad_manifest_exits_2_naming_the_field(make_package, capsys, command, label, mutate, field, message):
    manifest = _package(make_package, mutate)
    _one_line_naming(*_cli(capsys, command, manifest), str(manifest), f"{field}: ", message)


def test_100k_deep_json(make_package, capsys):
    manifest = make_package()
    manifest.write_text('{"version": 1, "ground_truth": ' + "[" * 100_000 + "]" * 100_000 + "}")
    _one_line_naming(*_cli(capsys, "validate", manifest), str(manifest), "nested deeper")


def test_deep_but_parseable_json(make_package, capsys):
    manifest = _package(make_package, _set(["ground_truth"], {"x": json.loads("[" * 500 + "]" * 500)}))
    _one_line_naming(*_cli(capsys, "validate", manifest), str(manifest), "ground_truth.x", "nested deeper")


def test_manifest_that_is_not_utf8(make_package, capsys):
    manifest = make_package()
    manifest.write_bytes(b'{"name": "\xff\xfe"}')
    _one_line_naming(*_cli(capsys, "validate", manifest), str(manifest), "not UTF-8")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_manifest_that_is_a_fifo(tmp_path):
    (tmp_path / "pkg").mkdir()
    os.mkfifo(tmp_path / "pkg" / "manifest.json")
    r = subprocess.run([sys.executable, "-m", "symdrive_core.cli", "validate", str(tmp_path / "pkg")],
                       cwd=Path(__file__).resolve().parents[2], capture_output=True, text=True, timeout=60)
    _one_line_naming(r.returncode, r.stderr, "manifest.json", "not a regular file")


# ------------------------------------------------------------------ images


def _png_declaring(path: Path, width: int, height: int) -> Path:
    """A PNG whose header says ``width`` x ``height`` (the pixels are not there)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\x00" * 16))
                     + chunk(b"IEND", b""))
    return path


# What is promised: refused before any pixel is allocated, in one line naming the file. Which rule
# says no depends on the image library: older OpenImageIO reads the header and the project's size
# rule refuses it; OpenImageIO 3.2 refuses a header claiming more bytes than the file could hold.
REFUSED = "(sides above 16384|cannot read image)"


@pytest.mark.parametrize("side,message", [(20_000, REFUSED), (100_000, "cannot read image")])
def test_image_declaring_a_huge_size(make_package, capsys, tmp_path, side, message):
    png = _png_declaring(tmp_path / "huge.png", side, side)
    with pytest.raises(InputError, match=rf"huge\.png: .*{message}") as exc:
        read_image(png)
    assert "\n" not in str(exc.value)
    manifest = make_package()
    d = json.loads(manifest.read_text())
    _png_declaring(manifest.parent / "huge.png", side, side)
    d["cameras"][0]["frames"][0]["image"] = "huge.png"
    manifest.write_text(json.dumps(d))
    code, err = _cli(capsys, "validate", manifest)
    _one_line_naming(code, err, str(manifest), "cameras[0].frames[0].image: huge.png")
    assert re.search(message, err), err


def test_a_png_cut_off_before_its_end_is_refused_by_validate(make_package, capsys):
    manifest = make_package()
    d = json.loads(manifest.read_text())
    cam = d["cameras"][0]
    image = write_image(manifest.parent / "front.png", np.random.default_rng(0).random((cam["height"], cam["width"], 3)))
    image.write_bytes(image.read_bytes()[: image.stat().st_size // 2])  # the header reads, the pixels run out
    cam["frames"][0]["image"] = image.name
    manifest.write_text(json.dumps(d))
    code, err = _cli(capsys, "validate", manifest)
    _one_line_naming(code, err, image.name, "cameras[0].frames[0].image", "truncated")


# ------------------------------------------------------------------ names are names, by property

_PIECES = st.sampled_from(["a", "b", "car", ".", "..", "/", "\\", "\x00", "\n", "\x7f", "\u0085", "é", "车", " ",
                           "C:", "~", "-", "_", "%2e", "\u2024", "\uff0f"])


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(parts=st.lists(_PIECES, min_size=0, max_size=8), prefix=st.sampled_from(["", "/", "\\", "../", "./"]))
def test_an_accepted_name_is_one_plain_file_name_inside_its_folder(tmp_path, parts, prefix):
    from symdrive_core.scene import check_name

    name = prefix + "".join(parts)
    schema_ok = _schema_accepts_name(name)
    try:
        check_name(name, "name")
    except InputError as exc:
        assert not schema_ok, name
        assert "\n" not in str(exc)
        return
    assert schema_ok, name
    root = tmp_path / "out"
    target = (root / name).resolve()
    assert target.parent == root.resolve() and target.name == name, name


_SCHEMA = json.loads(SCHEMA_PATH.read_text())


def _schema_accepts_name(name: str) -> bool:
    try:
        jsonschema.validate(name, _SCHEMA["properties"]["name"])
        return True
    except jsonschema.ValidationError:
        return False


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(parts=st.lists(st.sampled_from(["a", "b.ply", "..", ".", "/", "\\", "link", "out"]), min_size=1, max_size=6),
       absolute=st.booleans())
def test_a_resolved_asset_path_is_inside_the_package(tmp_path_factory, parts, absolute):
    from symdrive_core.scene.paths import real

    base = tmp_path_factory.mktemp("pkg")
    root = base / "p"
    (root / "a").mkdir(parents=True)
    (base / "secret").mkdir(exist_ok=True)
    (root / "link").symlink_to(base / "secret", target_is_directory=True)
    (root / "a" / "b.ply").write_bytes(b"ply\n")
    rel = ("/" if absolute else "") + "".join(parts)
    manifest_path = root / "manifest.json"
    from tests.conftest import manifest_dict

    d = manifest_dict(actors=())
    d["background"]["splats"] = rel
    manifest_path.write_text(json.dumps(d))
    m = load_manifest(manifest_path)
    try:
        full = m.resolve(m.background_splats)
    except InputError as exc:
        assert "background.splats" in str(exc)
        return
    assert real(full).is_relative_to(real(root)), rel


def test_numbers_json_cannot_write_are_refused(make_package, capsys):
    manifest = make_package()
    text = manifest.read_text().replace('"wlh": [1.8, 4.5, 1.5]', '"wlh": [1.8, 1e400, 1.5]')
    assert "1e400" in text
    manifest.write_text(text)
    _one_line_naming(*_cli(capsys, "validate", manifest), str(manifest), "actors[0].wlh", "finite")
    assert np.isinf(json.loads(text)["actors"][0]["wlh"][1])


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(parts=st.lists(st.sampled_from(["out", "a", ".", "..", "/", "\\", "\x00", "\n", "C:", "é", " ", "..x"]),
                      min_size=0, max_size=7))
def test_schema_and_loader_agree_on_every_output(tmp_path, parts):
    from symdrive_core.scene import check_relative

    value = "".join(parts)
    try:
        jsonschema.validate(value, _SCHEMA["properties"]["output"])
        schema_ok = True
    except jsonschema.ValidationError:
        schema_ok = False
    try:
        check_relative(value, "output")
    except InputError:
        assert not schema_ok, value
        return
    assert schema_ok, value
    root = tmp_path / "pkg"
    target = Path(os.path.normpath(root / value))
    assert target.is_relative_to(root) and target != root, value
