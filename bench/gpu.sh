#!/usr/bin/env bash
# GPU figures on a lent GPU machine, in one short run (this project's own machine has no GPU).
#
#   here:       make gpu-pack            # the twins the run reads, copied into .gpu_data/ (a few MB, git-ignored)
#   on the GPU: bash bench/gpu.sh        # make setup, then bench/bench_gpu.py; results in $OUT (else results/)
#
# The GPU machine needs PyPI for `make setup` (torch, sionna-rt, ...). Every figure is measured there, CUDA beside
# that machine's CPU, and written to bench_gpu.{json,md}; copy them into docs/ with the device named.
set -euo pipefail
cd "$(dirname "$0")/.."
export DTRADAR_DATA_ROOT="${DTRADAR_DATA_ROOT:-$PWD/.gpu_data}"
[ -x .venv/bin/python ] || make setup
.venv/bin/python -c "import torch, drjit as dr; print('torch cuda:', torch.cuda.is_available(), '| drjit cuda:', dr.has_backend(dr.JitBackend.CUDA))"
.venv/bin/python bench/bench_gpu.py --out "${OUT:-results}" "$@"
