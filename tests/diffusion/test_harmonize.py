import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from symdrive_core.diffusion.harmonize import harmonize, repaint_moves
from symdrive_core.diffusion.latent import VAESpace

from .helpers import OracleRestorer, tiny_builtin, tiny_flux


def scene(seed=0, h=24, w=32):
    rng = np.random.default_rng(seed)
    image = rng.random((h, w, 3)).astype(np.float32)
    region = np.zeros((h, w), bool)
    region[6:15, 9:22] = True
    return image, region


def test_moves_without_jumps_walk_straight_down():
    assert repaint_moves(5, 2) == [(2, 3), (3, 4), (4, 5)]


@settings(max_examples=30, deadline=None)
@given(
    steps=st.integers(2, 30), start=st.integers(0, 10), jump=st.integers(1, 6), resamples=st.integers(1, 4)
)
def test_moves_with_jumps_end_at_zero_noise_and_resample_each_jump_point(steps, start, jump, resamples):
    start = min(start, steps - 1)
    moves = repaint_moves(steps, start, jump, resamples)
    pos = start
    for i, j in moves:
        assert i == pos and (j == i + 1 or j == i - jump)
        pos = j
    assert pos == steps
    ups = [m for m in moves if m[1] < m[0]]
    points = len(range(start + jump, steps, jump))
    assert len(ups) == points * (resamples - 1)
    assert sum(1 for m in moves if m[1] > m[0]) == steps - start + len(ups) * jump


@pytest.mark.parametrize("jump,resamples,n_start,samples", [(0, 1, 0, 1), (0, 1, 4, 1), (3, 3, 2, 1), (0, 1, 2, 3)])
def test_background_comes_back_bit_identical(jump, resamples, n_start, samples):
    image, region = scene()
    out = harmonize(
        tiny_builtin(),
        image,
        region,
        steps=10,
        n_start=n_start,
        seed=3,
        jump_length=jump,
        resamples=resamples,
        samples=samples,
    )
    assert out.dtype == image.dtype
    assert np.array_equal(out[~region], image[~region])
    assert not np.allclose(out[region], image[region])  # the region did evolve


def test_background_bit_identical_behind_a_vae():
    transformer, vae = tiny_flux()
    from symdrive_core.diffusion.flux import FluxRestorer

    from .helpers import prompt_embeddings

    restorer = FluxRestorer(transformer, vae, *prompt_embeddings())
    image, region = scene(1, 16, 24)
    image = image.astype(np.float64)  # the input's own dtype and bits survive
    out = harmonize(restorer, image, region, steps=3, n_start=1)
    assert out.dtype == np.float64
    assert np.array_equal(out[~region], image[~region])


@pytest.mark.parametrize("jump,resamples", [(0, 1), (2, 3)])
def test_region_follows_the_model_and_the_rest_follows_the_input(jump, resamples):
    image, region = scene(2)
    y = np.full_like(image, 0.25)
    oracle = OracleRestorer(torch.from_numpy(y).permute(2, 0, 1)[None])
    out = harmonize(oracle, image, region, steps=8, n_start=0, jump_length=jump, resamples=resamples)
    assert np.allclose(out[region], 0.25, atol=1e-5)
    assert np.array_equal(out[~region], image[~region])
    left, right = oracle.calls[0]
    assert torch.equal(left, right)  # conditioned [z_insert ; z_t ; z_insert]
    assert torch.equal(left, torch.from_numpy(image).permute(2, 0, 1)[None] * 2 - 1)


def test_empty_region_returns_a_copy_and_bad_shapes_fail():
    image, region = scene()
    out = harmonize(tiny_builtin(), image, np.zeros_like(region))
    assert np.array_equal(out, image) and out is not image
    with pytest.raises(ValueError, match="share H, W"):
        harmonize(tiny_builtin(), image, region[:-1])


def test_latent_mask_covers_every_masked_pixel():
    from symdrive_core.diffusion.latent import latent_mask

    m = torch.zeros(1, 1, 9, 9)
    m[0, 0, 4, 5] = 1
    lm = latent_mask(m, 2)
    assert lm.shape[-2:] == (5, 5) and lm[0, 0, 2, 2] == 1 and lm.sum() == 1


def test_vae_space_uses_flux_normalisation():
    _, vae = tiny_flux()
    space = VAESpace(vae)
    assert (space.scale, space.shift, space.factor, space.channels) == (0.3611, 0.1159, 2, 4)
