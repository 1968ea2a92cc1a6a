"""Names of the diffusion stack that callers outside ``diffusion/`` read without loading torch:
the methods ``restore --evaluate`` scores and the shipped weights. The stages' numeric defaults
are config dataclasses in :mod:`.config`.
"""

from __future__ import annotations

from pathlib import Path

# The lateral methods ``restore --evaluate`` scores (see diffusion.restore): the restorer's ablation
# and chains, the geometry-guided warp alone, and the same restorations guided by it.
EVALUATED_METHODS = ("single_view", "ar_d0.5", "ar_d1.0", "warp", "geo_single_view", "geo_ar_d0.5", "geo_ar_d1.0")
# The shipped restorer weights; where the guided one ships, the geometry-guided methods sample with it
# (trained with the warp and its mask as conditions, on a family of streets:
# scripts/train_restorer_family.sh) and everything else with the default. Named here so the planner
# can read their metadata without torch.
DEFAULT_WEIGHTS = Path(__file__).with_name("weights") / "restorer.safetensors"
GUIDED_WEIGHTS = DEFAULT_WEIGHTS.with_name("restorer_geo.safetensors")
