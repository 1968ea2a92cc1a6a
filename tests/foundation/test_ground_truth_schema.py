"""``ground_truth`` has a schema: what the project writes loads, a misspelled key is an error
naming the file and the field, and the loader agrees with jsonschema on the same definition."""

import copy
import json

import jsonschema
import pytest

from symdrive_core.cli import main
from symdrive_core.scene import load_manifest, parse_manifest
from symdrive_core.scene.manifest import SCHEMA_PATH, ManifestError
from symdrive_core.world.demo import DEMO_PACKAGE
from tests.conftest import manifest_dict

SCHEMA = json.loads(SCHEMA_PATH.read_text(encoding="utf-8"))
DEMO = json.loads((DEMO_PACKAGE / "manifest.json").read_text(encoding="utf-8"))

TRAFFIC_GT = {
    "road": {"centerline": [[0.0, 0.0, 0.0], [50.0, 0.0, 0.0]], "lanes": 2, "lane_width": 3.5, "oncoming": 1},
    "traffic": {"density_per_km_lane": 20.0, "seconds": 10.0, "seed": 0, "speed_mps": 10.0, "time_offset_s": 2.0,
                "vehicles": 3, "vehicles_at_start": 2, "sumo_seconds": 0.12,
                "gaps": {"min_gap_m": 4.2, "frame": 3, "pair": ["a", "b"], "overlaps": []},
                "manoeuvres": [{"kind": "hard_brake", "vehicle": "veh0", "started": 1.0, "speed_before": 9.5,
                                "finished": 3.0}],
                "network": "traffic/road.net.xml", "routes": "traffic/routes.rou.xml"},
    "source": "../demo/manifest.json",
}


def _demo_with(edit) -> dict:
    d = copy.deepcopy(DEMO)
    edit(d["ground_truth"])
    return d


def _schema_errors(d: dict) -> list[str]:
    return [e.json_path for e in jsonschema.Draft202012Validator(SCHEMA).iter_errors(d)]


def test_the_schema_is_valid_and_takes_what_the_project_writes():
    jsonschema.Draft202012Validator.check_schema(SCHEMA)
    assert _schema_errors(DEMO) == []
    d = manifest_dict()
    d["ground_truth"] = TRAFFIC_GT
    assert _schema_errors(d) == []
    d["ground_truth"] = {"camera": "front", "train_frames": [0, 2], "heldout_frames": [1]}  # importers
    assert _schema_errors(d) == []


def test_the_demo_and_a_traffic_block_load(tmp_path):
    assert load_manifest(DEMO_PACKAGE).ground_truth["road"]["lanes"] == 2
    d = manifest_dict()
    d["ground_truth"] = TRAFFIC_GT
    assert parse_manifest(d, tmp_path / "manifest.json").ground_truth["traffic"]["vehicles"] == 3


CASES = [
    ("ground_truth.lateral[3].offset_m", "finite number", lambda gt: gt["lateral"][3].update(offset_m="left")),
    ("ground_truth.lateral[0].offset", "did you mean 'offset_m'?",
     lambda gt: gt["lateral"][0].update(offset=gt["lateral"][0].pop("offset_m"))),
    ("ground_truth.heldout", "did you mean 'heldout_frames'?", lambda gt: gt.update(heldout=[1])),
    ("ground_truth.insertion[1].shadowmask", "did you mean 'shadow_mask'?",
     lambda gt: gt["insertion"][1].update(shadowmask="x.png")),
    ("ground_truth.insertion[0].pose.rotation", "expected 4 numbers", lambda gt: gt["insertion"][0]["pose"].update(
        rotation=[1, 0, 0])),
    ("ground_truth.road.lane_widht", "did you mean 'lane_width'?", lambda gt: gt["road"].update(lane_widht=3.0)),
    ("ground_truth.road.lanes", ">= 1", lambda gt: gt["road"].update(lanes=0)),
    ("ground_truth.generator.sed", "did you mean 'seed'?", lambda gt: gt["generator"].update(sed=1)),
    ("ground_truth.lateral[2].frames.x", "frame indices", lambda gt: gt["lateral"][2]["frames"].update(x="a.png")),
    ("ground_truth.lateral[1].frames.99", "out of range",
     lambda gt: gt["lateral"][1]["frames"].update({"99": "a.png"})),
    ("ground_truth.insertion[2].camera", "no camera", lambda gt: gt["insertion"][2].update(camera="back")),
    ("ground_truth.train_frames[1]", ">= 0", lambda gt: gt["train_frames"].__setitem__(1, -1)),
    ("ground_truth.lanes.recorde", "did you mean 'recorded'?",
     lambda gt: gt["lanes"].update(recorde=gt["lanes"].pop("recorded"))),
    ("ground_truth.lanes.lateral[0].offset", "did you mean 'offset_m'?",
     lambda gt: gt["lanes"]["lateral"][0].update(offset=gt["lanes"]["lateral"][0].pop("offset_m"))),
    ("ground_truth.lanes.recorded.x", "frame indices", lambda gt: gt["lanes"]["recorded"].update(x="a.png")),
    ("ground_truth.lanes.lateral[4].frames.99", "out of range",
     lambda gt: gt["lanes"]["lateral"][4]["frames"].update({"99": "a.png"})),
    ("ground_truth.lanes.camera", "no camera", lambda gt: gt["lanes"].update(camera="back")),
    ("ground_truth.lanes", "ground_truth.road is missing", lambda gt: gt.pop("road")),
]


@pytest.mark.parametrize("field, message, edit", CASES, ids=[c[0] for c in CASES])
def test_a_wrong_field_is_an_error_naming_it(tmp_path, field, message, edit):
    with pytest.raises(ManifestError) as exc:
        parse_manifest(_demo_with(edit), tmp_path / "manifest.json")
    assert exc.value.field == field and message in exc.value.message, str(exc.value)


@pytest.mark.parametrize("field, message, edit", CASES, ids=[c[0] for c in CASES])
def test_jsonschema_refuses_the_same_where_the_schema_can_say_it(field, message, edit):
    if "out of range" in message or "no camera" in message or "road is missing" in message:
        pytest.skip("cross-field checks are the loader's alone")
    assert _schema_errors(_demo_with(edit))


def test_the_command_line_exits_2_naming_the_file_and_the_field(tmp_path, capsys):
    d = _demo_with(lambda gt: gt["lateral"][3].update(offset_m="left"))
    path = tmp_path / "manifest.json"
    path.write_text(json.dumps(d), encoding="utf-8")
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "ground_truth.lateral[3].offset_m" in err and err.count("\n") == 1
