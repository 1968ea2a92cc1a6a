#!/usr/bin/env bash
# Reproduce the shipped guided restorer (symdrive_core/diffusion/weights/restorer_geo.*): the
# built-in street's guided restorer (scripts/train_restorer_geo.sh) continued on a family of streets
# (scripts/street_family.py: generated streets that vary what a new drive varies, and the built-in
# street), every street's pairs drawn as one set, 3000 steps with three quarters of each batch
# from a degraded render, as that recipe trains it (about 15 minutes on two threads).
#   scripts/train_restorer_family.sh [FAMILY_DIR] [WORK_DIR] [START]
#   (defaults: out/family, out/restorer-family, out/geo-train/run/restorer.safetensors)
set -euo pipefail
cd "$(dirname "$0")/.."
FAMILY=${1:-out/family}
WORK=${2:-out/restorer-family}
START=${3:-out/geo-train/run/restorer.safetensors}
export NUMBA_NUM_THREADS=2 OMP_NUM_THREADS=2
mapfile -t PAIRS < <(python -c "import json, sys; [print(s['pairs']) for s in json.load(open(sys.argv[1]))['streets']]" \
  "$FAMILY/family.json")

symdrive train-restorer "${PAIRS[@]}" --out "$WORK/geo" --guide --init "$START" \
  --iters 3000 --seed 2 --threads 2 --degraded-fraction 0.75 --resume
cp "$WORK/geo/restorer.safetensors" symdrive_core/diffusion/weights/restorer_geo.safetensors
cp "$WORK/geo/restorer.json" symdrive_core/diffusion/weights/restorer_geo.json
