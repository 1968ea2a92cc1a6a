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


def test_crop_boxes_grow_align_and_clip_at_the_image_edges():
    from symdrive_core.diffusion.harmonize import crop_boxes

    region = np.zeros((40, 64), bool)
    region[13:20, 21:30] = True
    assert crop_boxes(region, 5, align=4) == [(8, 28, 16, 36)]  # 13-5 -> 8, 20+5 -> 28
    assert crop_boxes(region, 0, align=1) == [(13, 20, 21, 30)]
    region[:] = False
    region[0:3, 60:64] = True  # touches the top and right edges
    (y0, y1, x0, x1), = crop_boxes(region, 6, align=8)
    assert (y0, y1, x0, x1) == (0, 16, 48, 64)  # the end is clipped to the image, not to a multiple
    assert crop_boxes(region, None) == [(0, 40, 0, 64)]
    assert crop_boxes(np.zeros((40, 64), bool), 6) == []


def test_crop_boxes_split_distant_parts_and_keep_near_ones_together():
    from symdrive_core.diffusion.harmonize import crop_boxes

    region = np.zeros((64, 256), bool)
    region[30:34, 10:20] = True
    region[30:34, 200:210] = True
    assert crop_boxes(region, 8, align=8) == [(16, 48, 0, 32), (16, 48, 192, 224)]
    region[28:36, 20:200] = True  # a bridge: one part
    assert crop_boxes(region, 8, align=8) == [(16, 48, 0, 224)]
    region = np.zeros((64, 64), bool)
    region[10, 10] = region[40, 40] = True  # apart on both axes, but the union box is no larger
    assert crop_boxes(region, 16, align=8) == [(0, 64, 0, 64)]


def test_crop_equals_the_whole_image_when_the_margin_covers_it():
    image, region = scene(4, 40, 48)
    kw = dict(steps=4, n_start=1, seed=2, samples=2)
    full = harmonize(tiny_builtin(), image, region, crop_margin=None, **kw)
    assert np.array_equal(harmonize(tiny_builtin(), image, region, crop_margin=1000, **kw), full)
    everywhere = np.ones_like(region)
    assert np.array_equal(harmonize(tiny_builtin(), image, everywhere, crop_margin=4, **kw),
                          harmonize(tiny_builtin(), image, everywhere, crop_margin=None, **kw))


@pytest.mark.parametrize("max_memory_gib", [None, 1e-4])
def test_cropped_regions_at_the_border_and_apart_change_only_their_pixels(max_memory_gib):
    rng = np.random.default_rng(5)
    image = rng.random((48, 160, 3)).astype(np.float32)
    region = np.zeros((48, 160), bool)
    region[0:9, 2:14] = True  # touches the top edge
    region[30:48, 140:160] = True  # the bottom-right corner
    net = tiny_builtin()
    calls = []
    velocity = net.velocity
    net.velocity = lambda z, *a: calls.append(tuple(z.shape[-2:])) or velocity(z, *a)
    out = harmonize(net, image, region, steps=4, n_start=1, samples=2, crop_margin=8,
                    max_memory_gib=max_memory_gib, tile=16, tile_overlap=4)
    assert np.array_equal(out[~region], image[~region])
    assert not np.allclose(out[region], image[region])
    assert max(h * w for h, w in calls) < 48 * 160 // 4  # two small crops (or their tiles), never the frame


def test_crop_keeps_the_whole_images_time_shift_and_conditions_on_the_crop():
    image, region = scene(6, 64, 96)
    y = np.full_like(image, 0.25)

    class Shifted(OracleRestorer):
        shapes = []

        def time_shift(self, shape):
            self.shapes.append(tuple(shape))
            return 0.5

        def velocity(self, z_t, t, cond_left, cond_right):
            self.calls.append((cond_left.clone(), cond_right.clone()))
            return (z_t - self.y[..., : z_t.shape[-2], : z_t.shape[-1]]) / t.reshape(-1, 1, 1, 1)

    oracle = Shifted(torch.from_numpy(y).permute(2, 0, 1)[None])
    out = harmonize(oracle, image, region, steps=5, n_start=0, samples=3, crop_margin=2)
    assert oracle.shapes == [(3, 3, 64, 96)]
    left, right = oracle.calls[0]
    assert torch.equal(left, right) and left.shape[-2:] == (13, 17)  # region [6:15, 9:22] grown by 2
    assert torch.equal(left[0], torch.from_numpy(image[4:17, 7:24]).permute(2, 0, 1) * 2 - 1)
    assert np.allclose(out[region], 0.25, atol=1e-5)
    assert np.array_equal(out[~region], image[~region])
