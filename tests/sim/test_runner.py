"""Episodes, report.json, videos and the ``symdrive sim`` command."""

import json

import numpy as np
import pytest

from symdrive_core.cli import main
from symdrive_core.sim import SimConfig
from symdrive_core.sim.runner import run
from symdrive_core.sim.scores import score_episode

from .conftest import DEMO

STATE_ONLY = SimConfig(render=False)


class RaisesOnOddSeeds:
    def reset(self, env, seed=None):
        self.env, self.seed = env, seed

    def act(self, obs):
        if self.seed % 2:
            raise RuntimeError("planner crashed")
        return np.array([0.0, 0.0])


class RaisesInConstructor:
    def __init__(self):
        raise ValueError("no weights")


def test_agent_raising_does_not_lose_other_episodes(tmp_path):
    report = run(DEMO, f"{__name__}:RaisesOnOddSeeds", 3, 0, tmp_path, STATE_ONLY, video=False)
    reasons = [e["end_reason"] for e in report["episodes"]]
    assert reasons == ["route_end", "agent_error", "route_end"]
    assert "planner crashed" in report["episodes"][1]["end_detail"]
    assert "RuntimeError" in report["episodes"][1]["traceback"]
    on_disk = json.loads((tmp_path / "report.json").read_text())
    assert [e["end_reason"] for e in on_disk["episodes"]] == reasons
    assert on_disk["summary"]["end_reasons"] == {"route_end": 2, "agent_error": 1}
    report = run(DEMO, f"{__name__}:RaisesInConstructor", 2, 0, tmp_path, STATE_ONLY, video=False)
    assert [e["end_reason"] for e in report["episodes"]] == ["agent_error"] * 2


def test_video_and_report(tmp_path):
    cfg = SimConfig(image_size=(32, 18), time_limit_s=0.3)
    report = run(DEMO, "idm", 1, 0, tmp_path, cfg)
    video = tmp_path / report["episodes"][0]["video"]
    assert video.parent == tmp_path and video.stat().st_size > 0
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(video))
    meta = next(reader)
    frames = list(reader)
    assert len(frames) == 4 and tuple(meta["size"]) == (32, 18)
    assert not [p for p in tmp_path.iterdir() if ".part" in p.name]


def test_pdm_score_definition():
    hist = [{"x": 0.1 * k, "y": 0.0, "yaw": 0.0, "v": 1.0, "progress": 0.1 * k, "ttc": None} for k in range(11)]
    s = score_episode(hist, 0.1, 2.0, "time_limit")
    assert s["route_completion"] == pytest.approx(0.5) and s["comfort"] == 1.0 and s["ttc"] == 1.0
    assert s["pdm_score"] == pytest.approx((5 * 1 + 2 * 1 + 5 * 0.5) / 12)
    hist[3]["ttc"] = 0.6
    assert score_episode(hist, 0.1, 2.0, None)["pdm_score"] == pytest.approx((2 + 5 * 0.5) / 12)
    assert score_episode(hist, 0.1, 2.0, "collision")["pdm_score"] == 0.0
    for failed in ("agent_error", "invalid_action"):  # an agent that fails drove nothing it chose to
        assert score_episode(hist, 0.1, 2.0, failed)["pdm_score"] == 0.0
    hist[5]["v"] = 2.0  # a 10 m/s^2 jolt
    assert score_episode(hist, 0.1, 2.0, None)["comfort"] == 0.0
    start = [dict(h, progress=h["progress"] + 0.5) for h in hist]  # from 0.5 m along the route to a 1.5 m goal
    assert score_episode(start, 0.1, 1.5, "route_end")["route_completion"] == pytest.approx(1.0)


def test_replaying_the_recorded_drive_completes_its_route(tmp_path):
    report = run(DEMO, "replay", 1, 0, tmp_path, SimConfig(render=False), video=False, progress=False)
    (episode,) = report["episodes"]
    assert episode["end_reason"] == "route_end" and episode["scores"]["route_completion"] == pytest.approx(1.0, abs=0.02)


def test_cli(tmp_path, capsys):
    assert main(["sim", str(DEMO), "--agent", "cut-in", "--episodes", "2", "--seed", "5", "--out",
                 str(tmp_path / "o"), "--no-render", "--no-video"]) == 0
    out = capsys.readouterr().out
    assert "episode 1 (seed 6)" in out and "mean PDMS" in out
    report = json.loads((tmp_path / "o" / "report.json").read_text())
    assert report["agent"] == "cut-in" and len(report["episodes"]) == 2
    assert main(["sim", str(DEMO), "--agent", "nosuch", "--out", str(tmp_path / "p")]) == 2
    assert main(["sim", str(DEMO), "--size", "0x3", "--out", str(tmp_path / "p")]) == 2


def test_bad_input_is_refused_before_any_output_is_made(tmp_path, capsys):
    from tests.conftest import manifest_dict

    bare = tmp_path / "bare"  # poses only: no splats to render views off the path from
    bare.mkdir()
    (bare / "manifest.json").write_text(json.dumps(manifest_dict(n_frames=5, actors=(), background=None)))
    (tmp_path / "a_file").write_text("mine")
    for package, extra, says in ((bare, ["--restore"], "background.splats: sim's restore needs"),
                                 (DEMO, [], "a_file: --out names a file"),
                                 (tmp_path / "missing", [], "missing")):
        out = tmp_path / "a_file" if says.startswith("a_file") else tmp_path / "out" / "deep"
        assert main(["sim", str(package), "--out", str(out), "--quiet", "--no-video", "--size", "16x9", *extra]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and says in err, err
        assert not (tmp_path / "out").exists() and (tmp_path / "a_file").read_text() == "mine"
