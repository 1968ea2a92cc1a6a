import numpy as np
import pytest
import torch

from symdrive_core.errors import InputError
from symdrive_core.insertion.features import crop_frechet, load_extractor, vehicle_crop

EXTRACTOR = '''
import torch
_W = torch.Generator().manual_seed(0)
W = torch.randn(3 * 16 * 16, 8, generator=_W)
def features(x):
    x = torch.nn.functional.interpolate(x, size=(16, 16), mode="area")
    return torch.tanh(x.reshape(len(x), -1) @ W / 10.0)
'''


def _crops(n, shift, seed):
    rng = np.random.default_rng(seed)
    return [np.clip(rng.uniform(0.2, 0.6, (64, 64, 3)) + shift, 0, 1).astype(np.float32) for _ in range(n)]


def test_frechet_with_a_random_extractor_from_a_file(tmp_path):
    (tmp_path / "feat.py").write_text(EXTRACTOR)
    fn = load_extractor(f"{tmp_path / 'feat.py'}:features")
    a, b = _crops(30, 0.0, 0), _crops(30, 0.0, 1)
    far = _crops(30, 0.3, 2)
    same = crop_frechet(fn, a, a)
    near = crop_frechet(fn, a, b)
    shifted = crop_frechet(fn, a, far)
    assert abs(same) < 1e-6 and near > 0 and shifted > 5 * near


def test_torchscript_and_module_extractors(tmp_path):
    model = torch.jit.script(torch.nn.Sequential(torch.nn.Flatten(), torch.nn.Linear(3 * 64 * 64, 4)))
    model.save(str(tmp_path / "ext.pt"))
    ts = load_extractor(str(tmp_path / "ext.pt"))
    assert ts(torch.zeros(2, 3, 64, 64)).shape == (2, 4)
    assert load_extractor("torch:flatten") is torch.flatten
    with pytest.raises(InputError):
        load_extractor("no_colon_here")
    with pytest.raises(InputError):
        load_extractor(str(tmp_path / "missing.py") + ":f")


def test_vehicle_crop_resizes_the_mask_box():
    img = np.zeros((30, 40, 3), np.float32)
    img[5:15, 10:30] = 1.0
    mask = img[..., 0] > 0
    crop = vehicle_crop(img, mask, size=32, margin=0)
    assert crop.shape == (32, 32, 3) and crop.min() > 0.99
