"""``wlh.json``: every form the project writes or documents, one reader, errors naming the field."""

import json
import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from symdrive_core.errors import InputError
from symdrive_core.io.wlh import read_wlh, read_wlh_info
from symdrive_core.traffic.assets import load_asset

DEMO = Path(__file__).resolve().parents[2] / "symdrive_core/data/demo_street/assets"


def _write(tmp_path, data) -> Path:
    p = tmp_path / "wlh.json"
    p.write_text(data if isinstance(data, str) else json.dumps(data))
    return p


@pytest.mark.parametrize("data, expected", [
    ([1.9, 4.7, 1.75], (1.9, 4.7, 1.75)),
    ({"w": 1.9, "l": 4.7, "h": 1.75}, (1.9, 4.7, 1.75)),
    ({"width": 1.9, "length": 4.7, "height": 1.75}, (1.9, 4.7, 1.75)),
    ({"wlh": [1.9, 4.7, 1.75], "units": "metres", "mesh": "mesh.obj"}, (1.9, 4.7, 1.75)),
    ({"wlh": {"w": 1.9, "l": 4.7, "h": 1.75}}, (1.9, 4.7, 1.75)),
    ([2, 5, 2], (2.0, 5.0, 2.0)),
])
def test_every_documented_form_reads_the_same_size(tmp_path, data, expected):
    wlh = read_wlh(_write(tmp_path, data))
    assert wlh == expected and all(isinstance(v, float) for v in wlh)


def test_the_demo_assets_the_core_ships_are_read():
    sizes = {d.name: read_wlh(d / "wlh.json") for d in sorted(DEMO.iterdir())}
    assert sizes == {"hatchback": (1.74, 4.0, 1.5), "sedan": (1.8, 4.6, 1.45), "suv": (1.9, 4.7, 1.75)}
    wlh, info = read_wlh_info(DEMO / "suv" / "wlh.json")
    assert info["mesh"] == "mesh.obj" and info["splats"] == "splats.ply" and "wlh" not in info


@pytest.mark.parametrize("data, field, words", [
    ([1.9, 4.7], "wlh", "three sizes"),
    ([1.9, 4.7, 1.75, 1.0], "wlh", "three sizes"),
    ({"wlh": [1.9, -4.7, 1.75]}, "wlh[1]", "positive"),
    ({"wlh": [1.9, 0, 1.75]}, "wlh[1]", "positive"),
    ([1.9, 4.7, "1.75"], "wlh[2]", "size in metres"),
    ([1.9, 4.7, True], "wlh[2]", "size in metres"),
    ([1.9, 4.7, None], "wlh[2]", "size in metres"),
    ([1.9, 4700.0, 1.75], "wlh[1]", "below 1000"),
    ({"w": 1.9, "l": 4.7}, "h", "missing 'h'"),
    ({"wlh": {"w": 1.9, "l": 4.7}}, "wlh", "missing 'h'"),
    ({"w": 1.9, "l": 4.7, "h": -1}, "h", "positive"),
    ({"size": [1, 2, 3]}, "w", "missing 'w'"),
    ({"wlh": "1.9 4.7 1.75"}, "wlh", "expected"),
    (3.0, "wlh", "expected"),
])
def test_bad_sizes_name_the_file_and_the_field(tmp_path, data, field, words):
    path = _write(tmp_path, data)
    with pytest.raises(InputError) as exc:
        read_wlh(path)
    assert exc.value.path == str(path) and exc.value.field == field
    assert words in str(exc.value) and "wlh.json" in str(exc.value)


@pytest.mark.parametrize("text", ["[1.9, NaN, 1.75]", "[1.9, Infinity, 1.75]", "[1.9, -Infinity, 1]"])
def test_non_finite_sizes_are_refused(tmp_path, text):
    with pytest.raises(InputError, match=r"wlh\[1\].*finite"):
        read_wlh(_write(tmp_path, text))


@pytest.mark.parametrize("text, words", [("", "not valid JSON"), ("{\"wlh\": [1, 2,", "not valid JSON"),
                                         (b"\xff\xfe[1, 2, 3]", "UTF-8")])
def test_unreadable_files_say_why(tmp_path, text, words):
    p = tmp_path / "wlh.json"
    p.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(InputError, match=words):
        read_wlh(p)
    with pytest.raises(InputError, match="not found"):
        read_wlh(tmp_path / "missing" / "wlh.json")


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(min_value=1e-3, max_value=999.0), min_size=3, max_size=3),
       st.sampled_from(["list", "short", "long", "wlh"]))
def test_any_valid_size_round_trips_in_every_form(tmp_path_factory, sizes, form):
    w, l, h = sizes
    data = {"list": [w, l, h], "short": {"w": w, "l": l, "h": h},
            "long": {"width": w, "length": l, "height": h}, "wlh": {"wlh": [w, l, h], "kind": "car"}}[form]
    path = _write(tmp_path_factory.mktemp("wlh"), data)
    assert read_wlh(path) == (w, l, h) and all(math.isfinite(v) for v in read_wlh(path))


def test_traffic_assets_read_sizes_through_the_same_reader(tmp_path):
    (tmp_path / "mesh.glb").write_bytes(b"glTF")
    _write(tmp_path, {"w": 1.8, "l": 4.2, "h": 1.5})
    a = load_asset(tmp_path, "car")
    assert tuple(a.wlh) == (1.8, 4.2, 1.5) and a.mesh.name == "mesh.glb" and a.splats is None
    _write(tmp_path, {"wlh": [1.8, 4.2, float("nan")]})
    with pytest.raises(InputError, match=r"wlh\[2\]"):
        load_asset(tmp_path, "car")
