#!/usr/bin/env bash
# The GPU figures of README's "Seeds on a GPU": ldn and ppo on cartpole-v1 at 10, 100 and
# 1,000 vmapped seeds (`make bench` section `seeds`), a few minutes on one GPU.
#
#   bash bench/gpu.sh OUTDIR        # writes OUTDIR/gpu_seeds.json and OUTDIR/nvidia-smi.txt
#
# It needs a python with JAX's CUDA plugin, flax and optax (PYTHON, default python3); it runs
# from the checkout (PYTHONPATH), so nothing is installed. Nothing in `make test` uses it.
set -euo pipefail
out=${1:?usage: bash bench/gpu.sh OUTDIR}
cd "$(dirname "$0")/.."
mkdir -p "$out"
python=${PYTHON:-python3}
nvidia-smi >"$out/nvidia-smi.txt" 2>&1 || true
"$python" -c "import jax; print(jax.__version__, jax.devices())"
PYTHONUNBUFFERED=1 PYTHONPATH=. "$python" -m bench.bench --sections seeds \
    --out "$out/gpu_seeds.json"
