#!/usr/bin/env bash
# Reproduce the shipped restorer weights (symdrive_core/diffusion/weights/restorer.*):
# render training pairs from the built-in street's SHIPPED reconstruction (the one restoration
# runs on), from the package's training frames only (the held-out frames stay unseen), with the
# degraded starts of six cycle reconstructions (about 10 minutes; 23 on a busy machine), then train
# on this CPU in two stages: 9000 steps from recorded starts (about 23 minutes on two threads; 27 on
# a busy machine), 3000 more with half of each batch started from a degraded render (about 8 minutes).
#   scripts/train_restorer.sh [WORK_DIR]        (default: out/restorer-train)
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${1:-out/restorer-train}
PACKAGE=symdrive_core/data/demo_street
export NUMBA_NUM_THREADS=2 OMP_NUM_THREADS=2

symdrive make-pairs "$PACKAGE" --offsets 0.5,1,1.5,2,2.5,3 --cycle=-3,-2,-1,1,2,3 --out "$WORK/pairs.safetensors"
# defaults: --output skip --t-max 0.85 --full-fraction 0.1 --batch 8 --crop 64 --lr 4e-4
symdrive train-restorer "$WORK/pairs.safetensors" --out "$WORK/stage1" --iters 9000 --ema 0.999 --seed 0 \
  --threads 2 --degraded-fraction 0
symdrive train-restorer "$WORK/pairs.safetensors" --out "$WORK/stage2" --init "$WORK/stage1/restorer.safetensors" \
  --iters 3000 --seed 1 --threads 2 --degraded-fraction 0.5
cp "$WORK/stage2/restorer.safetensors" "$WORK/stage2/restorer.json" symdrive_core/diffusion/weights/
