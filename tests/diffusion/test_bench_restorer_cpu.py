"""``scripts/bench_restorer_cpu.py`` measures each inference option against eager float32 in one
run; the option the toolkit keeps (channels-last) gives eager's image to far below an 8-bit level,
and an option that cannot run is reported, not a crash."""

import json

from tests.scripts import load_script


def test_channels_last_gives_eagers_image_and_missing_runtimes_are_reported(tmp_path, monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_openvino(name, *args, **kwargs):  # as on a machine without it
        if name == "openvino":
            raise ImportError("No module named 'openvino'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_openvino)
    out = tmp_path / "bench.json"
    assert load_script("bench_restorer_cpu").main(["--width", "72", "--height", "40", "--threads", "1", "--repeat", "1",
                           "--only", "channels_last,openvino", "--json", str(out)]) == 0
    rows = {r["option"]: r for r in json.loads(out.read_text())["rows"]}
    assert rows["eager"]["speedup"] == 1.0 and rows["eager"]["max_diff_levels"] == 0.0
    assert rows["channels_last"]["seconds"] > 0 and rows["channels_last"]["max_diff_levels"] < 0.05
    assert "ImportError" in rows["openvino"]["error"]
