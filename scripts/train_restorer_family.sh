#!/usr/bin/env bash
# Train both restorers on a family of streets (scripts/street_family.py: generated streets that vary
# what a new drive varies, and the built-in street), by the recipes of scripts/train_restorer.sh
# and scripts/train_restorer_geo.sh with every street's pairs drawn as one set: the unguided
# restorer 9000 steps from recorded starts and 3000 more with half of each batch from a degraded
# render, then the guided one extended from it, 6000 steps. One pairs file per street serves both
# (the unguided stages leave its warps unread).
#   scripts/train_restorer_family.sh [FAMILY_DIR] [WORK_DIR]   (defaults: out/family, out/restorer-family)
set -euo pipefail
cd "$(dirname "$0")/.."
FAMILY=${1:-out/family}
WORK=${2:-out/restorer-family}
export NUMBA_NUM_THREADS=2 OMP_NUM_THREADS=2
mapfile -t PAIRS < <(python -c "import json, sys; [print(s['pairs']) for s in json.load(open(sys.argv[1]))['streets']]" \
  "$FAMILY/family.json")

symdrive train-restorer "${PAIRS[@]}" --out "$WORK/stage1" --iters 9000 --ema 0.999 --seed 0 --threads 2 \
  --degraded-fraction 0 --resume
symdrive train-restorer "${PAIRS[@]}" --out "$WORK/stage2" --init "$WORK/stage1/restorer.safetensors" \
  --iters 3000 --seed 1 --threads 2 --degraded-fraction 0.5 --resume
symdrive train-restorer "${PAIRS[@]}" --out "$WORK/geo" --guide --init "$WORK/stage2/restorer.safetensors" \
  --iters 6000 --seed 2 --threads 2 --degraded-fraction 0.75 --resume
echo "weights: $WORK/stage2/restorer.* (unguided), $WORK/geo/restorer.* (guided)"
