import json
import subprocess
import sys

import pytest

from symdrive_core.cli import main
from symdrive_core.io.ply import write_splats
from tests.optim.conftest import synthetic_package  # noqa: F401  (fixture)


def test_registering_the_commands_loads_no_torch_or_diffusers():
    code = (
        "import sys, symdrive_core.cli.diffusion as c, argparse; "
        "c.add_commands(argparse.ArgumentParser().add_subparsers()); "
        "print(sorted(m for m in ('torch', 'diffusers', 'peft') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_pairs_train_restore_evaluate_refine_from_the_command_line(synthetic_package, tmp_path, capsys):  # noqa: F811
    root, truth = synthetic_package
    ply = tmp_path / "recon.ply"
    write_splats(ply, truth)
    pairs = tmp_path / "pairs.safetensors"
    assert (
        main(
            ["make-pairs", str(root), "--gaussians", str(ply), "--offsets", "0.5,1", "--out", str(pairs),
             "--cycle=-1,1", "--cycle-iters", "10", "--cycle-max-gaussians", "5000"]
        )
        == 0
    )
    assert (
        main(
            [
                "train-restorer",
                str(pairs),
                "--out",
                str(tmp_path / "run"),
                "--iters",
                "3",
                "--width",
                "8",
                "--crop",
                "16",
                "--batch",
                "2",
                "--threads",
                "1",
                "--degraded-fraction",
                "1",
            ]
        )
        == 0
    )
    weights = tmp_path / "run" / "restorer.safetensors"
    record = json.loads((tmp_path / "run" / "restorer.json").read_text())
    assert record["command"].startswith("symdrive ") and record["steps"] == 3
    assert record["data"]["cycle_offsets"] == [-1.0, 1.0] and record["config"]["degraded_fraction"] == 1.0

    common = [
        "--gaussians",
        str(ply),
        "--weights",
        str(weights),
        "--steps",
        "2",
        "--n-start",
        "1",
        "--threads",
        "1",
    ]
    out = tmp_path / "eval"
    assert (
        main(
            [
                "restore",
                str(root),
                *common,
                "--out",
                str(out),
                "--evaluate",
                "--refine",
                "--refine-iters",
                "2",
                "--offsets",
                "0.5,1",
            ]
        )
        == 0
    )
    metrics = json.loads((out / "metrics.json").read_text())
    # refinement trains on the restored views of every recorded frame, not only the scored ones
    assert metrics["refine"]["frames"] == list(range(6)) and metrics["refine"]["restored_views"] == 6 * 4
    rows = metrics["lateral"]
    assert {(r["offset_m"], r["method"]) for r in rows} == {
        (o, m) for o in (-0.5, 0.5) for m in ("raw_3dgs", "single_view", "ar_d0.5", "ar_d1.0", "warp", "geo_single_view",
                                        "geo_ar_d0.5", "geo_ar_d1.0", "refined", "refined_recorded_only")
    }
    assert all(r["frames"] == 3 and 0 < r["ssim"] <= 1 for r in rows)
    assert (out / "refined.ply").exists()
    out = tmp_path / "eval-some"
    argv = ["restore", str(root), *common, "--out", str(out), "--evaluate", "--frames", "0", "--refine",
            "--refine-iters", "1", "--refine-frames", "0,3", "--offsets", "0.5", "--step", "0"]
    assert main(argv) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["refine"]["frames"] == [0, 3] and metrics["refine"]["restored_views"] == 2 * 2
    assert metrics["refine"]["step_m"] == 0.0  # single-view restorations serve refinement as well

    # at strength 0 every view is its start: the warp for the guided chain, the render for the other
    out = tmp_path / "eval-start"
    capsys.readouterr()
    assert main(["restore", str(root), *common, "--out", str(out), "--evaluate", "--frames", "0,1", "--offsets", "0.5",
                 "--methods", "warp,geo_single_view,ar_d1.0", "--strength", "0"]) == 0
    assert "symdrive restore: warning: frame(s) 1 have no lateral ground truth: not scored" in capsys.readouterr().err
    psnr = {r["method"]: r["psnr"] for r in json.loads((out / "metrics.json").read_text())["lateral"]}
    assert psnr["geo_single_view"] == psnr["warp"] and psnr["ar_d1.0"] == psnr["raw_3dgs"]
    with pytest.raises(SystemExit) as exc:
        main(["restore", str(root), *common, "--out", str(out), "--strength", "1.5"])
    assert exc.value.code == 2
    for flags in (["--methods", "warp"], ["--evaluate", "--refine-iters", "2"]):
        assert main(["restore", str(root), *common, "--out", str(tmp_path / "unused"), *flags]) == 2
        assert f"{flags[-2]}: is used by --" in capsys.readouterr().err

    out = tmp_path / "views"
    assert main(["restore", str(root), *common, "--out", str(out), "--offsets", "1", "--frames", "0,4",
                 "--geometry-guided"]) == 0
    index = json.loads((out / "restored.json").read_text())
    assert [(v["frame"], v["offset_m"]) for v in index["views"]] == [(0, -1.0), (0, 1.0), (4, -1.0), (4, 1.0)]
    assert index["sampler"]["keep_warp"] is None  # the weights' choice
    free = tmp_path / "views-free"
    assert main(["restore", str(root), *common, "--out", str(free), "--offsets", "1", "--frames", "0",
                 "--geometry-guided", "--no-keep-warp"]) == 0
    assert json.loads((free / "restored.json").read_text())["sampler"]["keep_warp"] is False
    assert all((out / v["image"]).exists() for v in index["views"])


def test_flux_backend_without_files_fails_with_the_list(synthetic_package, tmp_path, capsys):  # noqa: F811
    root, truth = synthetic_package
    ply = tmp_path / "recon.ply"
    write_splats(ply, truth)
    assert (
        main(
            [
                "restore",
                str(root),
                "--gaussians",
                str(ply),
                "--out",
                str(tmp_path / "o"),
                "--backend",
                "flux",
                "--flux-vae",
                str(tmp_path / "vae"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert "not given: transformer, lora, prompt" in err


def test_make_pairs_rejects_bad_offsets_before_any_work(tmp_path, capsys):
    out = tmp_path / "pairs.safetensors"
    for flag in ("--cycle=0", "--cycle=1,0", "--offsets=-1", "--offsets=0.5,0"):
        with pytest.raises(SystemExit) as exc:
            main(["make-pairs", str(tmp_path / "no-package"), flag, "--out", str(out)])
        assert exc.value.code == 2
        assert f"argument {flag.split('=')[0]}" in capsys.readouterr().err
    assert not out.exists()


def test_restore_rejects_frames_the_camera_does_not_have(synthetic_package, tmp_path, capsys):  # noqa: F811
    root, truth = synthetic_package
    ply = tmp_path / "recon.ply"
    write_splats(ply, truth)
    out = tmp_path / "o"
    for flags in (["--frames", "6"], ["--evaluate", "--refine", "--refine-frames", "0,9"]):
        assert main(["restore", str(root), "--gaussians", str(ply), "--out", str(out), *flags]) == 2
        assert f"{flags[-2]} {flags[-1].split(',')[-1]} is not a frame of camera 'front'" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("flags", [
    ["--ema", "nan"], ["--ema", "2"], ["--lr", "nan"], ["--lr", "-1"], ["--t-max", "0"], ["--t-max", "-1"],
    ["--full-fraction", "5"], ["--degraded-fraction", "nan"], ["--output", "foo"], ["--seed", "99999999999999999999"],
])
def test_train_restorer_refuses_values_that_train_nothing_usable(tmp_path, capsys, flags):
    """NaN EMA trained a restorer of NaN weights that restored black views, exit 0."""
    with pytest.raises(SystemExit) as exc:
        main(["train-restorer", str(tmp_path / "p.safetensors"), "--out", str(tmp_path / "run"), *flags])
    assert exc.value.code == 2 and f"argument {flags[0]}" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("flags, says", [
    (["--step", "1e-300"], "at least 0.01 m"), (["--step", "inf"], "at least 0.01 m"),
    (["--offsets", "1,1.004"], "distinct distances to the centimetre"), (["--seed", "-1"], "at least 0"),
])
def test_restore_refuses_steps_and_offsets_it_cannot_serve(tmp_path, capsys, flags, says):
    """A 1e-300 m chain step grew memory without bound; offsets alike to the centimetre shared one folder."""
    with pytest.raises(SystemExit) as exc:
        main(["restore", str(tmp_path / "pkg"), "--out", str(tmp_path / "o"), *flags])
    assert exc.value.code == 2 and says in capsys.readouterr().err


def test_outputs_of_the_wrong_kind_are_refused_before_any_work(synthetic_package, tmp_path, capsys):  # noqa: F811
    root, truth = synthetic_package
    ply = tmp_path / "recon.ply"
    write_splats(ply, truth)
    a_file, a_folder = tmp_path / "file", tmp_path / "folder"
    a_file.write_text("mine")
    a_folder.mkdir()
    for argv, says in (
        (["restore", str(root), "--out", str(a_file)], "--out names a file"),
        (["make-pairs", str(root), "--out", str(a_folder)], "--out names a folder"),
        (["make-pairs", str(root), "--gaussians", str(ply), "--out", str(tmp_path / "p.safetensors"), "--frames", "9"],
         "--frames 9 is not a frame of camera 'front'"),
        (["insert-eval", str(root), "--gaussians", "x.ply", "--assets-out", str(a_file)], "--assets-out names a file"),
        (["bench", "accuracy-time", "--package", str(root), "--out", str(a_file)], "--out names a file"),
        (["restore", str(root), "--gaussians", str(ply), "--out", str(tmp_path)], "no symdrive command wrote"),
        (["insert", str(root), "--actor", "car", "--out", str(tmp_path)], "no symdrive command wrote"),
    ):
        assert main(argv) == 2
        assert says in capsys.readouterr().err
    assert a_file.read_text() == "mine" and not any(a_folder.iterdir()) and not (tmp_path / "p.safetensors").exists()
