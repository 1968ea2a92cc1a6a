#!/usr/bin/env bash
# Train both restorers on a family of streets (scripts/street_family.py: generated streets that vary
# what a new drive varies, and the built-in street), every street's pairs drawn as one set. Each
# continues the built-in street's restorer (scripts/train_restorer.sh, scripts/train_restorer_geo.sh)
# as that recipe's last stage does: the guided one 3000 steps with three quarters of each batch
# from a degraded render, the unguided one 3000 steps with half. One pairs file per street serves
# both (the unguided restorer leaves its warps unread).
#   scripts/train_restorer_family.sh [FAMILY_DIR] [WORK_DIR]   (defaults: out/family, out/restorer-family)
set -euo pipefail
cd "$(dirname "$0")/.."
FAMILY=${1:-out/family}
WORK=${2:-out/restorer-family}
WEIGHTS=symdrive_core/diffusion/weights
export NUMBA_NUM_THREADS=2 OMP_NUM_THREADS=2
mapfile -t PAIRS < <(python -c "import json, sys; [print(s['pairs']) for s in json.load(open(sys.argv[1]))['streets']]" \
  "$FAMILY/family.json")

symdrive train-restorer "${PAIRS[@]}" --out "$WORK/geo" --guide --init "$WEIGHTS/restorer_geo.safetensors" \
  --iters 3000 --seed 2 --threads 2 --degraded-fraction 0.75 --resume
symdrive train-restorer "${PAIRS[@]}" --out "$WORK/unguided" --init "$WEIGHTS/restorer.safetensors" \
  --iters 3000 --seed 1 --threads 2 --degraded-fraction 0.5 --resume
echo "weights: $WORK/geo/restorer.* (guided), $WORK/unguided/restorer.* (unguided)"
