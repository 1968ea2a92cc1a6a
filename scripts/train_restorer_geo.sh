#!/usr/bin/env bash
# The built-in street's geometry-guided restorer, where the shipped one starts
# (scripts/train_restorer_family.sh continues it on a family of streets): pairs from the street's
# shipped reconstruction and training frames only, with the degraded starts of four cycle
# reconstructions and each frame's ground warp made from the other training frames (about 6
# minutes), then the shipped restorer extended with the warp and its mask as zero-initialised
# inputs and fine-tuned on this CPU (6000 steps, about 15 minutes on two threads).
#   scripts/train_restorer_geo.sh [WORK_DIR]        (default: out/geo-train; the weights: WORK_DIR/run/)
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${1:-out/geo-train}
PACKAGE=symdrive_core/data/demo_street
export NUMBA_NUM_THREADS=2 OMP_NUM_THREADS=2

symdrive make-pairs "$PACKAGE" --offsets 0.5,1,1.5,2,2.5,3 --cycle=-3,-1.5,1.5,3 --warps \
  --out "$WORK/pairs.safetensors"
symdrive train-restorer "$WORK/pairs.safetensors" --out "$WORK/run" --guide \
  --init symdrive_core/diffusion/weights/restorer.safetensors --iters 6000 --seed 2 --threads 2 \
  --degraded-fraction 0.75
