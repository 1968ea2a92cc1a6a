"""Optimisation: losses, 3DGS reconstruction, colour/opacity fine-tuning, refinement."""
