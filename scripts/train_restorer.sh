#!/usr/bin/env bash
# Reproduce the shipped restorer weights (symdrive_core/diffusion/weights/restorer.*):
# reconstruct the built-in street, render training pairs from it, train on this CPU.
#   scripts/train_restorer.sh [WORK_DIR]        (default: out/restorer-train)
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${1:-out/restorer-train}
PACKAGE=symdrive_core/data/demo_street
export NUMBA_NUM_THREADS=2 OMP_NUM_THREADS=2

symdrive reconstruct "$PACKAGE" --out "$WORK/recon" --no-link --iters 200 --seed 0
symdrive make-pairs "$PACKAGE" --gaussians "$WORK/recon/background.ply" \
    --offsets 0.5,1,1.5,2,2.5,3 --out "$WORK/pairs.safetensors"
symdrive train-restorer "$WORK/pairs.safetensors" --out "$WORK/run" --steps 1500 --ema 0.998 --seed 0 --threads 1
cp "$WORK/run/restorer.safetensors" "$WORK/run/restorer.json" symdrive_core/diffusion/weights/
