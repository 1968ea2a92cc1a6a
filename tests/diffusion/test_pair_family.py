"""Pairs of several streets drawn as one set (``PairFamily``) and training on them."""

import json

import numpy as np
import pytest
import torch
from safetensors.numpy import load_file, save_file

from symdrive_core.cli import main
from symdrive_core.diffusion.data import PairFamily, PairSet
from symdrive_core.diffusion.train import TrainConfig, train_restorer
from symdrive_core.errors import InputError
from tests.diffusion.test_data_train import CFG, synthetic_pairs


def flat_pairs(path, n, h, w, values):
    """``n`` pairs of flat images: left, target and right one grey level each (which file a crop
    came from, and whether it was mirrored, reads off its values)."""
    views = {k: np.full((n, h, w, 3), v, np.uint8) for k, v in zip(("left", "target", "right"), values)}
    save_file({**views, "offset": np.ones(n, np.float32)}, str(path))
    return path


def test_one_file_draws_exactly_its_own_batches(tmp_path):
    path = synthetic_pairs(tmp_path / "p.safetensors")
    one = PairSet(path).batch(16, 12, torch.Generator().manual_seed(3))
    family = PairFamily([path]).batch(16, 12, torch.Generator().manual_seed(3))
    assert all(torch.equal(a, b) for a, b in zip(one[:4], family[:4])) and family[4] is None


def test_files_of_other_sizes_share_batches_by_their_pairs(tmp_path):
    small = flat_pairs(tmp_path / "a.safetensors", 6, 20, 28, (10, 20, 30))
    large = flat_pairs(tmp_path / "b.safetensors", 18, 24, 36, (200, 210, 220))
    family = PairFamily([small, large])
    assert len(family) == 24 and not family.has_degraded
    g = torch.Generator().manual_seed(0)
    from_large = 0
    for _ in range(10):
        left, target, right, start, guide = family.batch(40, 64, g)
        assert left.shape == (40, 3, 20, 20) and guide is None  # the crop the smallest images hold
        assert torch.equal(start, target)
        for k in range(40):
            seen = tuple(round(float(v[k].mean()) * 255) for v in (left, target, right))
            assert seen in {(10, 20, 30), (30, 20, 10), (200, 210, 220), (220, 210, 200)}
            from_large += seen[1] == 210
    assert 0.65 < from_large / 400 < 0.85  # 18 of 24 pairs: 0.75


def test_files_made_differently_are_refused_by_name(tmp_path):
    plain = synthetic_pairs(tmp_path / "plain.safetensors")
    data = load_file(str(plain))
    data |= {"frame": np.arange(6, dtype=np.int32), "degraded": data["target"],
             "degraded_frame": np.arange(6, dtype=np.int32), "degraded_offset": np.ones(6, np.float32)}
    save_file(data, str(tmp_path / "cycles.safetensors"))
    with pytest.raises(InputError, match=r"cycles\.safetensors: has degraded starts .*unlike plain"):
        PairFamily([plain, tmp_path / "cycles.safetensors"])
    with pytest.raises(InputError, match=r"plain\.safetensors: has no degraded starts"):
        PairFamily([tmp_path / "cycles.safetensors", plain])


def test_training_on_a_family_records_every_file(tmp_path):
    a = synthetic_pairs(tmp_path / "a.safetensors", seed=1)
    b = synthetic_pairs(tmp_path / "b.safetensors", n=4, h=24, w=30, seed=2)
    record = train_restorer([a, b], tmp_path / "run", TrainConfig(steps=3, **CFG), progress=False)
    files = record["data"]["files"]
    assert [f["file"] for f in files] == ["a.safetensors", "b.safetensors"] and [f["pairs"] for f in files] == [6, 4]
    assert len({f["sha256"] for f in files}) == 2 and record["data"]["pairs"] == 10
    assert np.isfinite(record["final_loss"])
    assert main(["train-restorer", str(a), str(b), "--out", str(tmp_path / "cli"), "--iters", "2", "--batch", "2",
                 "--crop", "16", "--width", "8", "--threads", "1", "--quiet"]) == 0
    saved = json.loads((tmp_path / "cli" / "restorer.json").read_text())
    assert saved["data"]["pairs"] == 10 and len(saved["data"]["files"]) == 2
    assert main(["train-restorer", str(a), str(b), "--out", str(tmp_path / "flux"), "--backend", "flux"]) == 2
