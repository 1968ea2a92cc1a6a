"""Small restorers for tests: a random tiny UNet, an exact oracle, and a tiny Flux stack."""

from __future__ import annotations

import torch

from symdrive_core.diffusion.latent import PixelSpace
from symdrive_core.diffusion.models import BuiltinRestorer
from symdrive_core.diffusion.unet import UNet, UNetConfig

TINY = UNetConfig(width=8, mults=(1, 2))


def tiny_builtin(seed: int = 0, random_output: bool = True) -> BuiltinRestorer:
    """A random tiny UNet; its zero-initialised output layer is re-drawn so it predicts non-zero v."""
    torch.manual_seed(seed)
    net = UNet(TINY)
    if random_output:
        torch.nn.init.normal_(net.out.weight, std=0.1)
    return BuiltinRestorer(net.eval())


class OracleRestorer:
    """The exact velocity field of a point mass at ``y``: ``v = (z - y) / t``.

    For ``z_t = (1 - t) y + t eps`` this is exactly ``eps - y``, so Euler integration lands on
    ``y`` whatever the number of steps: a sampler that does not is wrong.
    """

    def __init__(self, y_image: torch.Tensor, latent=None):
        self.latent = latent or PixelSpace()
        self.y = self.latent.encode(y_image)
        self.calls = []

    def time_shift(self, latent_shape) -> float:
        return 0.0

    def velocity(self, z_t, t, cond_left, cond_right):
        self.calls.append((cond_left.clone(), cond_right.clone()))
        return (z_t - self.y) / t.reshape(-1, 1, 1, 1)


def tiny_flux(seed: int = 0):
    """A random ``FluxTransformer2DModel`` and ``AutoencoderKL`` from config (no download)."""
    from diffusers import AutoencoderKL, FluxTransformer2DModel

    torch.manual_seed(seed)
    transformer = FluxTransformer2DModel(
        patch_size=1,
        in_channels=16,
        num_layers=1,
        num_single_layers=1,
        attention_head_dim=16,
        num_attention_heads=2,
        joint_attention_dim=32,
        pooled_projection_dim=32,
        guidance_embeds=True,
        axes_dims_rope=(4, 6, 6),
    )
    vae = AutoencoderKL(
        in_channels=3,
        out_channels=3,
        down_block_types=("DownEncoderBlock2D",) * 2,
        up_block_types=("UpDecoderBlock2D",) * 2,
        block_out_channels=(8, 16),
        layers_per_block=1,
        latent_channels=4,
        norm_num_groups=4,
        scaling_factor=0.3611,
        shift_factor=0.1159,
        use_quant_conv=False,
        use_post_quant_conv=False,
        mid_block_add_attention=False,
    )
    return transformer.eval(), vae.eval()


def prompt_embeddings(seed: int = 0, tokens: int = 5):
    g = torch.Generator().manual_seed(seed)
    return torch.randn(tokens, 32, generator=g), torch.randn(32, generator=g)
