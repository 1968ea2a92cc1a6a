import json

import numpy as np
import pytest
import torch
from safetensors.numpy import load_file, save_file

from symdrive_core.diffusion.data import PairSet, make_pairs
from symdrive_core.diffusion.models import load_builtin
from symdrive_core.diffusion.train import TrainConfig, train_restorer
from symdrive_core.errors import InputError
from symdrive_core.scene import load_manifest
from symdrive_core.scene.camera import CameraView
from symdrive_core.splat.render import SplatRenderer
from tests.optim.conftest import synthetic_package  # noqa: F401  (fixture)


def test_make_pairs_renders_the_symmetric_cameras(synthetic_package, tmp_path):  # noqa: F811
    root, truth = synthetic_package
    manifest = load_manifest(root)
    out = make_pairs(
        manifest, truth, [0.5, 1.0], tmp_path / "pairs.safetensors", frames=[0, 3], progress=False
    )
    data = load_file(str(out))
    assert data["left"].shape == (4, 32, 48, 3) and data["left"].dtype == np.uint8
    assert data["offset"].tolist() == [0.5, 1.0, 0.5, 1.0] and data["frame"].tolist() == [0, 0, 3, 3]
    view = CameraView.of_frame(manifest.cameras[0], 3)
    render = SplatRenderer(truth)
    expect_left, expect_right = render(view.shifted(-1.0)), render(view.shifted(1.0))
    assert np.abs(data["left"][3] / 255.0 - expect_left).max() <= 0.5 / 255 + 1e-6
    assert np.abs(data["right"][3] / 255.0 - expect_right).max() <= 0.5 / 255 + 1e-6
    assert not np.array_equal(data["left"][3], data["right"][3])
    with pytest.raises(ValueError, match="positive"):
        make_pairs(manifest, truth, [-1.0], tmp_path / "x.safetensors", progress=False)


def synthetic_pairs(path, n=6, h=20, w=28, seed=0):
    """Target = mean of left and right, smooth random images: learnable in a few dozen steps."""
    rng = np.random.default_rng(seed)
    ys, xs = np.mgrid[0:h, 0:w]

    def smooth():
        f = rng.uniform(0.05, 0.3, 2)
        p = rng.uniform(0, 6, 3)
        return np.stack([0.5 + 0.4 * np.sin(f[0] * xs + f[1] * ys + p[c]) for c in range(3)], -1)

    left = np.stack([smooth() for _ in range(n)])
    right = np.stack([smooth() for _ in range(n)])
    target = (left + right) / 2
    q = lambda a: np.clip(np.rint(a * 255), 0, 255).astype(np.uint8)
    save_file(
        {"left": q(left), "target": q(target), "right": q(right), "offset": np.ones(n, np.float32)}, str(path)
    )
    return path


def test_batches_mirror_by_flipping_and_swapping(tmp_path):
    data = PairSet(synthetic_pairs(tmp_path / "p.safetensors"))
    left, target, right, start, _ = data.batch(64, 12, torch.Generator().manual_seed(0))
    assert torch.equal(start, target)  # no degraded starts in this file
    assert left.shape == (64, 3, 12, 12)
    crops = {}
    for i in range(len(data)):
        for y in range(20 - 11):
            for x in range(28 - 11):
                views = [v[i, :, y : y + 12, x : x + 12] for v in (data.left, data.target, data.right)]
                crops[views[1].numpy().tobytes()] = views
                mirror = [v.flip(-1) for v in reversed(views)]
                crops[mirror[1].numpy().tobytes()] = mirror + ["mirrored"]
    mirrored = 0
    for k in range(64):  # every crop is a plain crop or the mirror of one (flipped, left <-> right)
        found = crops[target[k].numpy().tobytes()]
        assert torch.equal(left[k], found[0]) and torch.equal(right[k], found[2])
        mirrored += len(found) == 4
    assert 10 < mirrored < 54


def test_missing_or_wrong_pairs_file_names_the_problem(tmp_path):
    with pytest.raises(InputError, match="not found"):
        PairSet(tmp_path / "none.safetensors")
    save_file({"left": np.zeros((1, 2, 2, 3), np.uint8)}, str(tmp_path / "bad.safetensors"))
    with pytest.raises(InputError, match="right, target"):
        PairSet(tmp_path / "bad.safetensors")



def test_broken_pairs_files_are_refused_naming_the_file_and_key(tmp_path):
    """Each ended in a library traceback, or trained on misaligned crops."""
    good = load_file(str(synthetic_pairs(tmp_path / "p.safetensors")))
    truncated = tmp_path / "truncated.safetensors"
    truncated.write_bytes((tmp_path / "p.safetensors").read_bytes()[:200])
    with pytest.raises(InputError, match="truncated.safetensors: not readable as a pairs file"):
        PairSet(truncated)
    for key, value, says in (
        ("left", good["left"][..., :1], "left: expected"),
        ("right", good["right"][0], "right: expected"),
        ("target", good["target"][:, ::2], "target: expected"),
        ("target", np.concatenate([good["target"], good["target"]]), "target: expected one per pair"),
    ):
        save_file({**good, key: np.ascontiguousarray(value)}, str(tmp_path / "bad.safetensors"))
        with pytest.raises(InputError, match=f"bad.safetensors: {says}"):
            PairSet(tmp_path / "bad.safetensors")

CFG = {
    "batch": 4,
    "crop": 16,
    "width": 8,
    "mults": (1, 2),
    "checkpoint_every": 3,
    "warmup": 2,
    "threads": 1,
    "lr": 2e-3,
}


def test_resume_continues_exactly(tmp_path):
    pairs = synthetic_pairs(tmp_path / "p.safetensors")
    straight = train_restorer(pairs, tmp_path / "a", TrainConfig(steps=6, **CFG), progress=False)
    train_restorer(pairs, tmp_path / "b", TrainConfig(steps=3, **CFG), progress=False)
    resumed = train_restorer(pairs, tmp_path / "b", TrainConfig(steps=6, **CFG), resume=True, progress=False)
    assert resumed["resumed_from"] == 3
    a = load_builtin(tmp_path / "a" / "restorer.safetensors").net.state_dict()
    b = load_builtin(tmp_path / "b" / "restorer.safetensors").net.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert straight["final_loss"] == resumed["final_loss"]
    record = json.loads((tmp_path / "a" / "restorer.json").read_text())
    assert (
        len(record["data"]["sha256"]) == 64
        and record["steps"] == 6
        and record["config"]["unet"]["width"] == 8
    )



def test_weights_and_checkpoints_that_cannot_serve_are_refused_naming_the_file(tmp_path):
    """NaN weights restored black views; a truncated file, a training checkpoint given as weights
    and a resume of another width gave tracebacks."""
    from symdrive_core.diffusion.models import save_builtin
    from symdrive_core.diffusion.unet import UNet, UNetConfig

    pairs = synthetic_pairs(tmp_path / "p.safetensors")
    train_restorer(pairs, tmp_path / "run", TrainConfig(steps=3, **CFG), progress=False)
    weights = tmp_path / "run" / "restorer.safetensors"
    (tmp_path / "cut.safetensors").write_bytes(weights.read_bytes()[:300])
    with pytest.raises(InputError, match="cut.safetensors: not readable as restorer weights"):
        load_builtin(tmp_path / "cut.safetensors")
    with pytest.raises(InputError, match="checkpoint.safetensors: not restorer weights"):
        load_builtin(tmp_path / "run" / "checkpoint.safetensors")
    net = UNet(UNetConfig(width=8, mults=(1, 2)))
    with torch.no_grad():
        net.out.weight.fill_(float("nan"))
    save_builtin(tmp_path / "nan.safetensors", net)
    with pytest.raises(InputError, match="nan.safetensors: 1 of .* hold NaN or infinity"):
        load_builtin(tmp_path / "nan.safetensors")
    with pytest.raises(InputError, match="checkpoint.safetensors: a checkpoint of another network"):
        train_restorer(pairs, tmp_path / "run", TrainConfig(steps=6, **{**CFG, "width": 16}), resume=True,
                       progress=False)

def test_training_learns_the_pair_to_centre_mapping(tmp_path):
    pairs = synthetic_pairs(tmp_path / "p.safetensors", n=8)
    # the velocity output: the skip output starts at the condition mean, which is this target
    cfg = TrainConfig(steps=300, ema=0.9, output="v", t_max=1.0, full_fraction=0.0, **CFG)
    record = train_restorer(pairs, tmp_path / "run", cfg, progress=False)
    curve = record["loss_every_100"]
    assert curve[-1] < 0.5 * curve[0]
    # the trained model restores a held-out centre view better than either side view does
    from symdrive_core.diffusion.sampler import SamplerConfig, restore_image

    held = PairSet(synthetic_pairs(tmp_path / "held.safetensors", n=2, seed=7))
    model = load_builtin(tmp_path / "run" / "restorer.safetensors")
    out = restore_image(model, held.left, held.right, None, SamplerConfig(steps=10, n_start=0))
    err = float(((out - held.target) ** 2).mean())
    assert err < float(((held.left - held.target) ** 2).mean())
    assert err < float(((held.right - held.target) ** 2).mean())


def test_training_continues_from_init_weights_and_records_cycles(tmp_path):
    pairs = synthetic_pairs(tmp_path / "p.safetensors")
    first = tmp_path / "a"
    train_restorer(pairs, first, TrainConfig(steps=3, **CFG), progress=False)
    # degraded starts: each frame gets one noisy copy of its target
    data = load_file(str(pairs))
    rng = np.random.default_rng(0)
    noisy = np.clip(data["target"].astype(int) + rng.integers(-40, 40, data["target"].shape), 0, 255)
    data |= {"frame": np.arange(6, dtype=np.int32), "degraded": noisy.astype(np.uint8),
             "degraded_frame": np.arange(6, dtype=np.int32), "degraded_offset": np.ones(6, np.float32)}
    save_file(data, str(tmp_path / "cyc.safetensors"), metadata={"cycle_offsets": "[1.0]"})
    frozen = {**CFG, "lr": 0.0}  # no learning: the result must be the init itself
    record = train_restorer(tmp_path / "cyc.safetensors", tmp_path / "b",
                            TrainConfig(steps=2, init=str(first / "restorer.safetensors"), **frozen), progress=False)
    a = load_builtin(first / "restorer.safetensors").net.state_dict()
    b = load_builtin(tmp_path / "b" / "restorer.safetensors").net.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert record["data"]["cycle_offsets"] == [1.0] and record["config"]["init"].endswith("restorer.safetensors")
    assert np.isfinite(record["final_loss"])
    with pytest.raises(InputError, match="not the one configured"):
        train_restorer(pairs, tmp_path / "c", TrainConfig(steps=1, init=str(first / "restorer.safetensors"),
                                                          **{**CFG, "width": 16}), progress=False)
