"""``symdrive flux-prompt``: the prompt-embedding file ``--backend flux`` reads, from local encoders.

Flux conditions on a T5 sequence (``prompt_embeds`` [L, 4096] for T5-XXL) and CLIP's pooled
output (``pooled_prompt_embeds`` [768] for CLIP-L), computed as ``FluxPipeline`` computes them:
T5 over the prompt padded to ``max_length`` tokens (512 for FLUX.1-dev), CLIP's pooler output
over the prompt padded to its 77 tokens. The restorer's prompt is fixed, so the encoders run
once here and never at restoration time.

``text_encoders`` is a folder laid out as the FLUX.1-dev repository is: ``text_encoder/`` (CLIP),
``tokenizer/``, ``text_encoder_2/`` (T5) and ``tokenizer_2/``. Everything loads with
``local_files_only=True``: nothing is downloaded.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch

from ..errors import InputError
from ..io.atomic import atomic_path
from .config import FLUX_PROMPT_TOKENS
from .pretrained import load_pretrained

DEFAULT_PROMPT = "a sharp, clean photo of a street seen from a car, road, lane markings, cars, buildings"
SUBFOLDERS = {"clip": "text_encoder", "clip_tokenizer": "tokenizer", "t5": "text_encoder_2", "t5_tokenizer": "tokenizer_2"}


def _check(root: Path) -> dict[str, Path]:
    if not root.is_dir():
        raise InputError(root, "text-encoder folder not found", "--text-encoders")
    paths = {k: root / sub for k, sub in SUBFOLDERS.items()}
    for key, folder in paths.items():
        probe = folder / ("tokenizer_config.json" if "tokenizer" in key else "config.json")
        if not probe.is_file():
            raise InputError(probe, f"not found (expected the {SUBFOLDERS[key]}/ folder of FLUX.1-dev)", "--text-encoders")
    return paths


@torch.no_grad()
def prompt_embeddings(text_encoders, text: str = DEFAULT_PROMPT, max_length: int = FLUX_PROMPT_TOKENS,
                      device: str = "cpu"):
    """``(prompt_embeds [L, D_t5], pooled_prompt_embeds [D_clip])`` in float32."""
    from transformers import AutoTokenizer, CLIPTextModel, T5EncoderModel

    paths = _check(Path(text_encoders))
    dtype = torch.bfloat16 if device.startswith("cuda") else torch.float32
    clip_tok = load_pretrained(AutoTokenizer, paths["clip_tokenizer"], "the CLIP tokenizer")
    t5_tok = load_pretrained(AutoTokenizer, paths["t5_tokenizer"], "the T5 tokenizer")
    clip = load_pretrained(CLIPTextModel, paths["clip"], "the CLIP text encoder", torch_dtype=dtype).to(device)
    ids = clip_tok(
        [text], padding="max_length", max_length=clip_tok.model_max_length, truncation=True, return_tensors="pt"
    ).input_ids
    pooled = clip(ids.to(device), output_hidden_states=False).pooler_output[0].float().cpu()
    del clip
    t5 = load_pretrained(T5EncoderModel, paths["t5"], "the T5 text encoder", torch_dtype=dtype).to(device)
    ids = t5_tok([text], padding="max_length", max_length=max_length, truncation=True, return_tensors="pt").input_ids
    embeds = t5(ids.to(device), output_hidden_states=False)[0][0].float().cpu()
    return embeds, pooled


def write_prompt_file(text_encoders, out, text: str = DEFAULT_PROMPT, max_length: int = FLUX_PROMPT_TOKENS,
                      device: str = "cpu") -> Path:
    """The ``.safetensors`` :func:`.flux.load_flux` reads (``prompt_embeds``, ``pooled_prompt_embeds``)."""
    from safetensors.torch import save_file

    embeds, pooled = prompt_embeddings(text_encoders, text, max_length, device)
    out = Path(out)
    meta = {"prompt": text, "max_length": str(max_length), "shapes": json.dumps([list(embeds.shape), list(pooled.shape)])}
    with atomic_path(out) as tmp:
        save_file({"prompt_embeds": embeds.contiguous(), "pooled_prompt_embeds": pooled.contiguous()}, str(tmp), metadata=meta)
    return out
