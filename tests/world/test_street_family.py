"""``scripts/street_family.py``: each street's variations come from its seed alone, stay in their
ranges, and reach ``make_world.py`` as the options it reads."""

import sys
from pathlib import Path

import pytest

from tests.scripts import SCRIPTS, load_script

family = load_script("street_family")


def test_a_street_is_drawn_from_its_seed_within_the_ranges():
    drawn = [family.street_settings(seed) for seed in range(100, 160)]
    assert drawn == [family.street_settings(seed) for seed in range(100, 160)]
    assert len({tuple(sorted(s.items())) for s in drawn}) == 60
    for s in drawn:
        assert 1.4 <= s["camera_height"] <= 2.0 and 1.0 <= s["pitch"] <= 6.0 and 18.0 <= s["lens_mm"] <= 32.0
        assert 0 <= s["material_jitter"] <= 0.25 and 0 <= s["noise"] <= 0.02 and 0 <= s["blur"] <= 1.0
        assert 0 <= s["exposure_jitter"] <= 0.15 and (s["width"], s["height"]) in family.SIZES
    assert {s["overcast"] for s in drawn} == {True, False}
    assert {(s["width"], s["height"]) for s in drawn} == set(family.SIZES)


def test_the_options_parse_as_make_world_reads_them():
    pytest.importorskip("bpy")
    if str(SCRIPTS) not in sys.path:
        sys.path.insert(0, str(SCRIPTS))
    make_world = load_script("make_world")
    for seed in (100, 108):  # sunlit and overcast
        s = family.street_settings(seed)
        args = make_world.parse_args(family.world_args(s, Path("street")))
        assert args.out == Path("street") and args.seed == seed and args.overcast == s["overcast"]
        assert args.offsets == [] and args.holdout_every == 0 and args.placements == 0 and args.frames == 30
        assert (args.width, args.height) == (s["width"], s["height"])
        for key in ("camera_height", "pitch", "lens_mm", "material_jitter", "noise", "blur", "exposure_jitter"):
            assert getattr(args, key) == s[key]
    measured = make_world.parse_args(family.world_args(family.street_settings(200), Path("m"), measured=True))
    assert measured.holdout_every == 5 and len(measured.offsets) == 10 and measured.placements == 0


def test_a_stopped_family_continues_where_it_stopped(tmp_path, monkeypatch):
    ran = []

    def fake_run(label, cmd, log):  # each step writes the output its skip test looks for
        ran.append(label)
        out = Path(cmd[cmd.index("--out") + 1])
        marker = {"street": out / "manifest.json", "reconstruction": out / "metrics.json", "pairs": out}[label]
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.write_text("{}")

    monkeypatch.setattr(family, "run", fake_run)
    s = family.street_settings(100)
    pairs = family.make_street(tmp_path / "street_100", s)
    assert ran == ["street", "reconstruction", "pairs"] and pairs.exists()
    (tmp_path / "street_100" / "reconstruction" / "metrics.json").unlink()  # stopped during its fit
    pairs.unlink()
    ran.clear()
    family.make_street(tmp_path / "street_100", s)
    assert ran == ["reconstruction", "pairs"]
    ran.clear()
    family.make_street(tmp_path / "street_100", s)
    assert ran == []
    family.make_street(tmp_path / "measured", family.street_settings(200), measured=True)
    assert ran == ["street", "reconstruction"]  # streets to measure on get no pairs


def test_a_failed_step_stops_the_family_naming_its_log(tmp_path):
    with pytest.raises(SystemExit, match=r"reconstruction failed \(exit 3\): see .*step\.log"):
        family.run("reconstruction", [sys.executable, "-c", "import sys; sys.exit(3)"], tmp_path / "step.log")
