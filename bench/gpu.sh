#!/usr/bin/env bash
# The GPU figures of docs/benchmarks.md ("MJX on a GPU", "Seeds on a GPU"): PPO on halfcheetah
# through MJX at 10, 100 and 1,000 vmapped seeds, 45 s of training each, with the wall time to
# a moving return of 2,000 at 1,000 seeds (section `mjx`), then ldn and ppo on cartpole-v1 at
# 10, 100 and 1,000 seeds (`make bench` section `seeds`). Each section runs under its own
# timeout (MJX_S, SEEDS_S seconds), so the whole stays under 8 minutes.
#
#   bash bench/gpu.sh OUTDIR   # writes OUTDIR/gpu_{mjx,seeds}.{json,log}, nvidia-smi.txt
#
# It needs a python with JAX's CUDA plugin, flax and optax (PYTHON, default python3); it runs
# from the checkout (PYTHONPATH), so nothing of ours is installed. MuJoCo and MJX, where that
# python lacks them, travel as cp312 wheels in .whl/ (ignored by git), fetched here with
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 \
#     --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux2014_x86_64 \
#     -d .whl mujoco==4.0.0 mujoco-core==4.0.0 mujoco-studio==4.0.0 mujoco-mjx==3.17.0 \
#     gymnasium==1.4.0 cloudpickle farama-notifications trimesh glfw pyopengl websockets
# and installed below into /tmp/site. Nothing in `make test` uses this script.
set -euo pipefail
out=${1:?usage: bash bench/gpu.sh OUTDIR}
cd "$(dirname "$0")/.."
mkdir -p "$out"
python=${PYTHON:-python3}
if compgen -G ".whl/*.whl" >/dev/null; then
    "$python" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl
    export PYTHONPATH=/tmp/site
fi
export PYTHONPATH=".${PYTHONPATH:+:$PYTHONPATH}"
nvidia-smi >"$out/nvidia-smi.txt" 2>&1 || true
"$python" -c "import jax; print(jax.__version__, jax.devices())"
status=0
PYTHONUNBUFFERED=1 timeout "${MJX_S:-330}" "$python" -m bench.bench --sections mjx \
    --out "$out/gpu_mjx.json" >"$out/gpu_mjx.log" 2>&1 || status=$?
tail -n 3 "$out/gpu_mjx.log"
PYTHONUNBUFFERED=1 timeout "${SEEDS_S:-120}" "$python" -m bench.bench --sections seeds \
    --out "$out/gpu_seeds.json" >"$out/gpu_seeds.log" 2>&1 || status=$?
tail -n 3 "$out/gpu_seeds.log"
exit "$status"
