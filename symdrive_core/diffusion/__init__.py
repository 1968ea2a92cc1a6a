"""Symmetric dual-view diffusion restoration and RePaint harmonization.

Modules: ``flow`` (schedule, Euler sampler, N_start initialisation), ``latent`` (pixel space /
Flux VAE), ``unet`` (the built-in network), ``models`` (backends and ``load_restorer``),
``flux`` (Flux.1-dev + LoRA), ``flux_prompt`` (its prompt embeddings from local text encoders),
``flux_train`` (its LoRA training), ``sampler`` (images in, image out), ``tiling`` (overlapping
tiles under a memory budget), ``data`` (training pairs), ``cycle`` (degraded starts from cycle
reconstructions), ``warp`` (recorded neighbours warped over the ground: the guided chain's
geometry), ``train``, ``adapt`` (the restorer fine-tuned on the drive it restores),
``restore`` (auto-regressive lateral chain, evaluation), ``refine`` (3DGS
refinement on restored views), ``harmonize`` (RePaint), ``config`` (the torch-free config
dataclasses: sampler per backend, training, refinement, cycles), ``defaults`` (names callers
outside read without torch; the command line is ``cli/diffusion.py``).

Design of the built-in backend, which must train on a CPU in minutes and ship in a few MB:

* **Pixel space at the package's resolution, not a latent.** The paper's VAE exists only as
  multi-GB Flux weights we may not download, a small VAE trained here would cap PSNR at its
  own reconstruction error, and at 256x144 the image is already as small as an SD latent of a
  2 MP frame. The harmonization guarantee (background bit-identical) is also simplest in
  pixels. Training uses random 64x64 crops (the network is fully convolutional), inference runs
  on whole frames.
* **Channel concatenation of ``[z_-d ; z_t ; z_d]``, not tokens.** The side views are a short
  lateral step away, so corresponding content sits near the same pixels: a convolutional UNet
  with nine input channels compares them locally for almost no extra cost, while in-context
  tokens triple the sequence length of every attention layer. Flux, whose attention is global
  anyway, gets the token layout (``flux``), as Kontext does.
* **A correction on the condition mean, trained where sampling runs.** The network's output is
  a preconditioned correction to the clean centre view on top of a blend of the noisy state and
  the mean of the two side views (``unet``), so an untrained or weak model starts from its
  inputs instead of from noise; and training draws ``t`` mostly from ``[0, t_max]``, the range
  the position-accurate start (``N_start``) actually visits (``train``, ``flow.training_times``).

Nothing here downloads anything: the built-in weights ship in ``weights/``, and Flux loads only
from files the user names.
"""
