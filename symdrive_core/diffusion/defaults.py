"""Defaults of the diffusion stages that callers outside ``diffusion/`` read without loading torch.

The command line (``cli/diffusion.py``) and the pipeline's ``StageOptions`` both start from
these, so a default is one edit and ``symdrive plan`` still never imports torch.
"""

from __future__ import annotations

from pathlib import Path

# (steps, n_start, samples) per backend; the built-in one's are measured (symdrive bench accuracy-time)
# and are pipeline.stages.StageOptions' defaults too; Flux keeps the paper's.
SAMPLER_DEFAULTS = {"builtin": (5, 4, 8), "flux": (50, 10, 1)}
# (iterations, densification cap) of each cycle reconstruction (make-pairs --cycle); data.make_pairs'
# and cycle.cycle_config's default too. About 1.5 minutes each on the built-in street.
CYCLE_DEFAULTS = (1000, 60000)
# The lateral methods ``restore --evaluate`` scores (see diffusion.restore): the restorer's ablation
# and chains, the geometry-guided warp alone, and the same restorations guided by it.
EVALUATED_METHODS = ("single_view", "ar_d0.5", "ar_d1.0", "warp", "geo_single_view", "geo_ar_d0.5", "geo_ar_d1.0")
# The shipped restorer weights; where the guided one ships, the geometry-guided methods sample with it
# (trained with the warp and its mask as conditions: scripts/train_restorer_geo.sh) and everything
# else with the default. Named here so the planner can read their metadata without torch.
DEFAULT_WEIGHTS = Path(__file__).with_name("weights") / "restorer.safetensors"
GUIDED_WEIGHTS = DEFAULT_WEIGHTS.with_name("restorer_geo.safetensors")
