import argparse
import json

import numpy as np
import pytest

from symdrive_core.cli import insertion as commands
from symdrive_core.errors import InputError
from symdrive_core.io.images import read_image, read_mask

from . import package


def _parse(argv):
    parser = argparse.ArgumentParser()
    commands.add_commands(parser.add_subparsers(dest="command"))
    return parser.parse_args(argv)


def test_insert_writes_frames_masks_and_regions(tmp_path):
    path, _ = package.write_package(tmp_path / "pkg")
    out = tmp_path / "out"
    args = _parse(["insert", str(path), "--actor", "insert_0", "--gaussians", str(path.parent / "background.ply"),
                   "--out", str(out)])
    assert args.func(args) == 0
    frame = out / "front" / f"{package.HELD:06d}"
    rgb = read_image(frame.with_suffix(".png"), channels=3)
    mask = read_mask(frame.with_suffix(".mask.png"))
    region = read_mask(frame.with_suffix(".region.png"))
    truth_mask = read_mask(path.parent / "gt/mask.png") > 0.5
    assert rgb.shape == (package.H, package.W, 3)
    assert ((mask > 0.5) == truth_mask).mean() > 0.98  # the same car in the same place
    assert np.all(region[mask > 0.5] > 0.5)
    assert len(list((out / "front").glob("*.mask.png"))) == 1  # the actor exists in one frame only
    assert not list((out / "front").glob("*.shadow.png"))  # no sun in this package


def test_insert_under_a_sun_writes_the_cast_shadow(tmp_path):
    path, _ = package.write_package(tmp_path / "pkg", sun=package.SUN)
    out = tmp_path / "out"
    args = _parse(["insert", str(path), "--actor", "insert_0", "--gaussians", str(path.parent / "background.ply"),
                   "--out", str(out)])
    assert args.func(args) == 0
    frame = out / "front" / f"{package.HELD:06d}"
    shade = read_mask(frame.with_suffix(".shadow.png")) > 0.5
    truth = read_mask(path.parent / "gt/shadow.png") > 0.5
    region = read_mask(frame.with_suffix(".region.png")) > 0.5
    assert (shade & truth).sum() >= 0.9 * truth.sum() and region[truth].all()
    lit = read_image(path.parent / "gt/without.png", channels=3)
    assert (read_image(frame.with_suffix(".png"), channels=3)[truth].sum(-1) < lit[truth].sum(-1)).all()


def test_insert_eval_baselines_to_json(tmp_path, capsys):
    path, _ = package.write_package(tmp_path / "pkg")
    args = _parse(["insert-eval", str(path), "--gaussians", str(path.parent / "background.ply"), "--no-harmonize",
                   "--json", str(tmp_path / "rows.json")])
    assert args.func(args) == 0
    rows = json.loads((tmp_path / "rows.json").read_text())["insertion"]
    assert [r["method"] for r in rows] == ["naive", "color_transfer"]
    for option in (["--finetune-iters", "5"], ["--assets-out", str(tmp_path / "assets")], ["--steps", "2"]):
        args = _parse(["insert-eval", str(path), "--gaussians", str(path.parent / "background.ply"), "--no-harmonize",
                       *option])
        with pytest.raises(InputError, match=f"{option[0]}: harmonizes and fine-tunes, which --no-harmonize leaves"):
            args.func(args)
    assert not (tmp_path / "assets").exists()


def test_insert_eval_harmonizes_with_the_weights_given(tmp_path):
    import torch

    from symdrive_core.diffusion.models import save_builtin
    from symdrive_core.diffusion.unet import UNet, UNetConfig

    path, _ = package.write_package(tmp_path / "pkg")
    torch.manual_seed(0)
    weights = save_builtin(tmp_path / "tiny.safetensors", UNet(UNetConfig(width=8, mults=(1, 2))))
    args = _parse(["insert-eval", str(path), "--gaussians", str(path.parent / "background.ply"),
                   "--weights", str(weights), "--steps", "2", "--samples", "2", "--finetune-iters", "2",
                   "--json", str(tmp_path / "rows.json")])
    assert args.func(args) == 0
    rows = json.loads((tmp_path / "rows.json").read_text())["insertion"]
    assert [r["method"] for r in rows] == ["naive", "color_transfer", "harmonized", "finetuned"]
    assert all(np.isfinite(r["masked_psnr"]) for r in rows)
    # a missing weights file is named, not replaced by the shipped one
    args = _parse(["insert-eval", str(path), "--gaussians", str(path.parent / "background.ply"),
                   "--weights", str(tmp_path / "absent.safetensors")])
    with pytest.raises(InputError, match="absent.safetensors"):
        args.func(args)
