"""Optimisation of Gaussians against views: losses, 3DGS reconstruction (with density control),
colour/opacity-only fine-tuning, and the held-out and lateral scorers. Refinement on restored
views is :mod:`symdrive_core.diffusion.refine` (it trains on the restorer's output)."""
