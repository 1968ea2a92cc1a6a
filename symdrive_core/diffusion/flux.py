"""Flux.1-dev + LoRA restorer through diffusers / peft, from files on the user's disk.

The three views travel as in-context tokens (Kontext style): the noisy centre latent is packed
into 2x2 patches (64 features per token for Flux's 16-channel VAE), the left and right
condition latents likewise, and the condition tokens are appended after the noisy ones. The
first position-id channel says which image a token belongs to (0 centre, 1 left, 2 right), the
other two its row and column, so the rotary embedding aligns the three grids. The prediction
is sliced back to the centre tokens and unpacked. The schedule is Flux's: sigmas shifted by a
``mu`` that grows with the token count. Text conditioning is a fixed prompt whose T5 / CLIP
embeddings are read from a file (no text encoder is loaded).

Nothing is downloaded: every path is local and checked before diffusers is touched.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import torch

from ..errors import InputError
from ..io.atomic import atomic_path
from .config import LORA_TARGETS
from .latent import VAESpace
from .pretrained import load_pretrained

VIEW_CENTRE, VIEW_LEFT, VIEW_RIGHT = 0, 1, 2


def pack(z: torch.Tensor) -> torch.Tensor:
    """[B, C, h, w] -> [B, (h/2)(w/2), 4C] tokens of 2x2 patches."""
    b, c, h, w = z.shape
    if h % 2 or w % 2:
        raise ValueError(f"latent size {h}x{w} must be even to pack 2x2 patches")
    z = z.reshape(b, c, h // 2, 2, w // 2, 2).permute(0, 2, 4, 1, 3, 5)
    return z.reshape(b, (h // 2) * (w // 2), 4 * c)


def unpack(tokens: torch.Tensor, h: int, w: int) -> torch.Tensor:
    """Inverse of :func:`pack` for a latent of size ``h x w``."""
    b, _, f = tokens.shape
    c = f // 4
    z = tokens.reshape(b, h // 2, w // 2, c, 2, 2).permute(0, 3, 1, 4, 2, 5)
    return z.reshape(b, c, h, w)


def position_ids(view: int, h: int, w: int) -> torch.Tensor:
    """[(h/2)(w/2), 3]: (view index, row, column) of every token of one packed latent."""
    rows, cols = torch.meshgrid(torch.arange(h // 2), torch.arange(w // 2), indexing="ij")
    return torch.stack([torch.full_like(rows, view), rows, cols], dim=-1).reshape(-1, 3).float()


def flux_mu(
    tokens: int,
    base_tokens: int = 256,
    max_tokens: int = 4096,
    base_shift: float = 0.5,
    max_shift: float = 1.15,
) -> float:
    """Flux's time-shift parameter, linear in the number of (noisy) image tokens."""
    m = (max_shift - base_shift) / (max_tokens - base_tokens)
    return tokens * m + base_shift - m * base_tokens


class FluxRestorer:
    """``velocity(z_t, t, left, right)`` with a Flux transformer over three token groups."""

    def __init__(
        self,
        transformer,
        vae,
        prompt_embeds: torch.Tensor,
        pooled_prompt_embeds: torch.Tensor,
        guidance: float = 3.5,
        model=None,
    ):
        self.transformer = transformer
        # the module called: ``transformer`` itself, or its multi-GPU wrapper while training
        self.model = transformer if model is None else model
        self.latent = VAESpace(vae)
        p = next(transformer.parameters())
        self.prompt_embeds = prompt_embeds.reshape(1, -1, prompt_embeds.shape[-1]).to(p.device, p.dtype)
        self.pooled = pooled_prompt_embeds.reshape(1, -1).to(p.device, p.dtype)
        self.guidance = guidance

    def time_shift(self, latent_shape) -> float:
        h, w = latent_shape[-2:]
        return flux_mu((h // 2) * (w // 2))

    def velocity(self, z_t, t, cond_left, cond_right) -> torch.Tensor:
        b, _, h, w = z_t.shape
        p = next(self.transformer.parameters())
        tokens = torch.cat([pack(z_t), pack(cond_left), pack(cond_right)], dim=1).to(p.device, p.dtype)
        ids = torch.cat([position_ids(v, h, w) for v in (VIEW_CENTRE, VIEW_LEFT, VIEW_RIGHT)]).to(p.device)
        txt = self.prompt_embeds.expand(b, -1, -1)
        guidance = None
        if self.transformer.config.guidance_embeds:
            guidance = torch.full((b,), self.guidance, device=p.device, dtype=p.dtype)
        out = self.model(
            hidden_states=tokens,
            encoder_hidden_states=txt,
            pooled_projections=self.pooled.expand(b, -1),
            timestep=t.to(p.device, p.dtype),
            img_ids=ids,
            txt_ids=torch.zeros(txt.shape[1], 3, device=p.device),
            guidance=guidance,
            return_dict=False,
        )[0]
        n = (h // 2) * (w // 2)
        return unpack(out[:, :n].float(), h, w).to(z_t.device)

    def parameters(self):
        """The trainable parameters: the LoRA weights when an adapter is attached."""
        return [q for q in self.transformer.parameters() if q.requires_grad]

    def train(self, mode: bool = True) -> FluxRestorer:
        self.transformer.train(mode)
        return self


# ------------------------------------------------------------------ LoRA


def add_lora(transformer, rank: int = 16, alpha: float | None = None, targets=LORA_TARGETS) -> None:
    """Attach a fresh trainable LoRA adapter (base weights frozen) for training."""
    from peft import LoraConfig

    transformer.requires_grad_(False)
    transformer.add_adapter(
        LoraConfig(
            r=rank, lora_alpha=alpha or rank, target_modules=list(targets), init_lora_weights="gaussian"
        )
    )


def save_lora(transformer, path: str | os.PathLike) -> Path:
    """The adapter's weights (diffusers key layout, ``transformer.`` prefix) + its config."""
    from peft.utils import get_peft_model_state_dict
    from safetensors.torch import save_file

    state = {
        f"transformer.{k}": v.detach().contiguous() for k, v in get_peft_model_state_dict(transformer).items()
    }
    cfg = transformer.peft_config["default"]
    meta = {
        "rank": str(cfg.r),
        "alpha": str(cfg.lora_alpha),
        "targets": json.dumps(sorted(cfg.target_modules)),
    }
    path = Path(path)
    with atomic_path(path) as tmp:
        save_file(state, str(tmp), metadata=meta)
    return path


def load_lora(transformer, path: str | os.PathLike) -> None:
    """Load a LoRA file (diffusers, kohya or other layouts diffusers converts) into the transformer."""
    from diffusers import FluxPipeline

    state = FluxPipeline.lora_state_dict(str(path), local_files_only=True)
    state = state[0] if isinstance(state, tuple) else state
    transformer.load_lora_adapter(state, prefix="transformer", adapter_name="restorer")
    transformer.set_adapters(["restorer"])


# ------------------------------------------------------------------ loading


@dataclass
class FluxFiles:
    transformer: Path  # diffusers folder: config.json + diffusion_pytorch_model*.safetensors
    vae: Path  # diffusers folder: config.json + diffusion_pytorch_model.safetensors
    lora: Path  # the restorer LoRA (.safetensors)
    prompt: Path  # .safetensors with prompt_embeds [L, 4096] and pooled_prompt_embeds [768]

    def missing(self) -> list[str]:
        out = []
        for folder in (self.transformer, self.vae):
            if not (folder / "config.json").is_file():
                out.append(str(folder / "config.json"))
            if not any(folder.glob("diffusion_pytorch_model*.safetensors")):
                out.append(str(folder / "diffusion_pytorch_model.safetensors") + " (or its shards + index)")
        for f in (self.lora, self.prompt):
            if not f.is_file():
                out.append(str(f))
        return out


def load_flux(
    transformer: str | os.PathLike | None = None,
    vae: str | os.PathLike | None = None,
    lora: str | os.PathLike | None = None,
    prompt: str | os.PathLike | None = None,
    *,
    dtype: torch.dtype = torch.bfloat16,
    device: str = "cpu",
    guidance: float = 3.5,
) -> FluxRestorer:
    """Build the Flux restorer from local files, or fail naming every file that is missing."""
    names = {"transformer": transformer, "vae": vae, "lora": lora, "prompt": prompt}
    unset = [k for k, v in names.items() if v is None]
    if unset:
        raise InputError(
            "flux",
            "the Flux backend needs local files; not given: "
            + ", ".join(unset)
            + ". Expected: transformer/ and vae/ diffusers folders (config.json + "
            "diffusion_pytorch_model*.safetensors, from FLUX.1-dev), the restorer LoRA "
            ".safetensors and a prompt-embedding .safetensors (prompt_embeds, pooled_prompt_embeds)",
        )
    files = FluxFiles(*(Path(names[k]) for k in ("transformer", "vae", "lora", "prompt")))
    missing = files.missing()
    if missing:
        raise InputError("flux", "missing files: " + "; ".join(missing))
    from diffusers import AutoencoderKL, FluxTransformer2DModel

    from ..io.tensor_file import read_tensor_file

    net = load_pretrained(FluxTransformer2DModel, files.transformer, "the FLUX.1-dev transformer", torch_dtype=dtype)
    ae = load_pretrained(AutoencoderKL, files.vae, "the FLUX.1-dev VAE", torch_dtype=dtype)
    load_lora(net, files.lora)
    emb, _ = read_tensor_file(files.prompt, "a prompt-embedding file")
    for key in ("prompt_embeds", "pooled_prompt_embeds"):
        if key not in emb:
            raise InputError(files.prompt, f"no tensor named {key!r}")
    return FluxRestorer(
        net.to(device).eval(),
        ae.to(device),
        emb["prompt_embeds"],
        emb["pooled_prompt_embeds"],
        guidance=guidance,
    )
