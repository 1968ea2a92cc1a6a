import copy
import json

import jsonschema
import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.scene import ManifestError, check_files, load_manifest, parse_manifest
from symdrive_core.scene.manifest import SCHEMA_PATH
from tests.conftest import manifest_dict


def _parse(d, tmp_path):
    return parse_manifest(d, tmp_path / "manifest.json")


def test_valid_manifest_loads_typed(tmp_path):
    m = _parse(manifest_dict(n_frames=4, actors=("a", "b"), lateral=(1.0, -1.0), sun=[0, 0, -2]), tmp_path)
    assert len(m.frames) == 4 and m.cameras[0].frames[3].K.shape == (3, 3)
    assert [a.id for a in m.actors] == ["a", "b"] and [a.instance_id for a in m.actors] == [1, 2]
    np.testing.assert_allclose(m.effects.sun_direction, [0, 0, -1])
    np.testing.assert_allclose(m.actor("b").pose(2).translation, [10.0, 1.0, 0.75])
    cf = m.cameras[0].frames[1]
    np.testing.assert_allclose(cf.world_to_camera @ cf.camera_to_world, np.eye(4), atol=1e-12)


def test_round_trip_through_save(tmp_path):
    m = _parse(manifest_dict(actors=("a",), lateral=(0.5,)), tmp_path)
    m.actors[0].poses[1] = None
    m.effects.shadow_ratio = 0.3
    path = m.save(tmp_path / "manifest.json")
    m2 = load_manifest(tmp_path)
    assert m2.to_json() == m.to_json() and m2.actors[0].poses[1] is None
    assert json.loads(path.read_text())["conventions"]["pixel_center"] == 0.5


def test_schema_accepts_what_the_loader_writes(tmp_path):
    schema = json.loads(SCHEMA_PATH.read_text())
    m = _parse(manifest_dict(actors=("a", "b"), sun=[1, 0, -1]), tmp_path)
    jsonschema.validate(m.to_json(), schema)
    jsonschema.validate(manifest_dict(), schema)


def _mutated(fn):
    d = manifest_dict(n_frames=3, actors=("a", "b", "c"))
    fn(d)
    return d


@pytest.mark.parametrize("mutate,field,message", [
    (lambda d: d["actors"][2]["poses"][1].update(rotation=[1, 0, 0]), r"actors\[2\]\.poses\[1\]\.rotation", "expected 4 numbers"),
    (lambda d: d["actors"][1]["poses"][0].update(rotation=[0, 0, 0, 0]), r"actors\[1\]\.poses\[0\]\.rotation", "zero quaternion"),
    (lambda d: d["actors"][0]["poses"].pop(), r"actors\[0\]\.poses", "expected 3 entries"),
    (lambda d: d["actors"][0].update(kind="parked"), r"actors\[0\]\.kind", "expected one of 'existing', 'inserted'"),
    (lambda d: d["actors"][1].update(id="a"), r"actors\[1\]\.id", "duplicate actor id"),
    (lambda d: d["actors"][0].update(wlh=[1, -2, 1]), r"actors\[0\]\.wlh\[1\]", "expected a value > 0"),
    (lambda d: d["actors"][0].update(assets={}), r"actors\[0\]\.assets", "splat PLY and/or a mesh"),
    (lambda d: d["cameras"][0]["frames"][2].update(K=[[1, 0, 0], [0, 1, 0]]), r"cameras\[0\]\.frames\[2\]\.K", "expected 3 rows"),
    (lambda d: d["cameras"][0]["frames"][1]["camera_to_world"][0].__setitem__(0, 2.0),
     r"cameras\[0\]\.frames\[1\]\.camera_to_world", "not a rigid transform"),
    (lambda d: d["cameras"][0]["frames"][1]["world_to_camera"][0].__setitem__(3, 99.0),
     r"cameras\[0\]\.frames\[1\]\.world_to_camera", "not the inverse"),
    (lambda d: d["cameras"][0].update(width=0), r"cameras\[0\]\.width", ">= 1"),
    (lambda d: d["frames"][2].update(timestamp=0.0), r"frames\[2\]\.timestamp", "increase"),
    (lambda d: d.pop("version"), "version", "required field is missing"),
    (lambda d: d.update(version=7), "version", "understands version 1"),
    (lambda d: d["effects"].update(sun_direction=[0, 0, 0]), r"effects\.sun_direction", "zero vector"),
    (lambda d: d["effects"].update(shadow_ratio=1.5), r"effects\.shadow_ratio", "expected a value <= 1"),
    (lambda d: d["effects"].update(shadow_ratio="dark"), r"effects\.shadow_ratio", "finite number"),
    (lambda d: d["effects"].update(lateral_offsets=[1, "x"]), r"effects\.lateral_offsets\[1\]", "finite number"),
    (lambda d: d.update(masks={"entries": [{"camera": "front", "frame": 0, "actor": "zz"}]}),
     r"masks\.entries\[0\]\.actor", "no actor with id 'zz'"),
    (lambda d: d.update(masks={"entries": [{"camera": "front", "frame": 9, "actor": "a"}]}),
     r"masks\.entries\[0\]\.frame", "out of range"),
    (lambda d: d.update(masks={"id_maps": [{"camera": "front", "frame": 0, "path": "x.png", "ids": {"0": "a"}}]}),
     r"masks\.id_maps\[0\]\.ids", "positive integer"),
])
def test_errors_name_the_field_path(tmp_path, mutate, field, message):
    with pytest.raises(ManifestError, match=f"manifest.json: {field}: .*{message}"):
        _parse(_mutated(mutate), tmp_path)


def test_check_files_names_missing_file(make_package):
    path = make_package()
    m = load_manifest(path)
    check_files(m)
    (path.parent / "car_0.ply").unlink()
    with pytest.raises(ManifestError, match=r"actors\[0\]\.assets\.splats: file not found: car_0\.ply"):
        check_files(m)



def _moved(d: dict, offset) -> dict:
    for cf in d["cameras"][0]["frames"]:
        c2w = np.array(cf["camera_to_world"])
        c2w[:3, 3] += offset
        cf["camera_to_world"], cf["world_to_camera"] = c2w.tolist(), np.linalg.inv(c2w).tolist()
    return d


def test_cameras_where_float32_steps_by_centimetres_load_with_a_warning(make_package, capsys, recwarn):
    """UTM coordinates are valid, but splat positions are float32 (half a metre at 4.5e6 m): the
    package loads and says so once, as one line on the command line; 1e5 m stays silent."""
    path = make_package()
    d = json.loads(path.read_text())
    path.write_text(json.dumps(_moved(copy.deepcopy(d), [1e5, -1e5, 0.0])))
    load_manifest(path)
    assert not [w for w in recwarn if "origin" in str(w.message)]
    path.write_text(json.dumps(_moved(copy.deepcopy(d), [5e5, 4.5e6, 0.0])))
    with pytest.warns(UserWarning, match=r"cameras up to 4500000 m from the origin, where the splats' float32 "
                                         r"positions step by 50 cm"):
        load_manifest(path)
    assert main(["validate", str(path), "--no-files"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("symdrive validate: warning: ") and "move the origin" in err[0]

def test_cli_validate_exit_codes(make_package, capsys):
    path = make_package()
    assert main(["validate", str(path)]) == 0
    assert "valid" in capsys.readouterr().out
    d = json.loads(path.read_text())
    bad = copy.deepcopy(d)
    bad["actors"][0]["poses"][1]["rotation"] = [1, 2]
    path.write_text(json.dumps(bad))
    assert main(["validate", str(path)]) == 2
    assert "actors[0].poses[1].rotation: expected 4 numbers" in capsys.readouterr().err
    path.write_text("{not json")
    assert main(["validate", str(path)]) == 2
    assert "not valid JSON" in capsys.readouterr().err


def test_cli_info(make_package, capsys):
    path = make_package()
    assert main(["info", str(path.parent / "car_0.ply")]) == 0
    out = capsys.readouterr().out
    assert "50 splats, SH degree 1" in out and "bounds min" in out
    assert main(["info", str(path.parent / "nope.ply")]) == 2


def _with_lateral_truth(path, image: str, offset=0.5):
    """The package at ``path`` with one lateral truth image of frame 0, ``image`` as written."""
    d = json.loads(path.read_text())
    d["ground_truth"] = {"camera": "front", "lateral": [{"offset_m": offset, "camera": "front",
                                                         "frames": {"0": image}}]}
    path.write_text(json.dumps(d))


@pytest.mark.parametrize("image, says", [
    ("nope.png", "file not found: nope.png"),
    ("../../etc/hostname", "is outside the package"),
    ("small.png", "image is 16x12, the camera is 32x24"),
])
def test_validate_checks_the_ground_truths_images_naming_their_field(make_package, capsys, image, says):
    from symdrive_core.io.images import write_image

    path = make_package()
    write_image(path.parent / "small.png", np.zeros((12, 16, 3), np.float32))
    _with_lateral_truth(path, image)
    out = path.parent.parent / "restored"
    for command in (["validate", str(path)], ["restore", str(path.parent), "--evaluate", "--out", str(out)]):
        assert main(command) == 2  # restore refuses before any work
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "ground_truth.lateral[0].frames.0" in err and says in err, err
    assert not out.exists()


def test_a_lateral_truth_offset_that_is_not_a_finite_number_is_refused(make_package, capsys):
    from symdrive_core.io.images import write_image

    path = make_package()
    write_image(path.parent / "gt.png", np.zeros((24, 32, 3), np.float32))
    _with_lateral_truth(path, "gt.png")
    assert main(["validate", str(path)]) == 0
    capsys.readouterr()
    _with_lateral_truth(path, "gt.png", offset=float("nan"))
    assert main(["validate", str(path)]) == 2
    assert "ground_truth.lateral[0].offset_m: expected a finite offset in metres, got nan" in capsys.readouterr().err
