"""The scorers are checked on the reconstruction tests' synthetic package (truth rendered from
known Gaussians)."""

from tests.optim.conftest import synthetic_package  # noqa: F401  (a fixture, used by name)
