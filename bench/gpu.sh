#!/usr/bin/env bash
# The GPU figures of docs/benchmarks.md ("MJX on a GPU", "Seeds on a GPU"). First the two not
# yet measured on a GPU: a fixed slice of the user's command (below, USER_S seconds at most)
# and SAC's update at 10 seeds (SAC_S). Then, as measured on 2026-12-04: PPO on halfcheetah
# through MJX at 10, 100 and 1,000 vmapped seeds (section `mjx`: each count trains whole
# chunks of 8,000 steps per seed until at least 45 s have passed after its compile, and
# records when the mean moving return first reached 2,000, which at 1,000 seeds takes far
# longer than that), then ldn and ppo on cartpole-v1 at 10, 100 and 1,000 seeds (`make bench`
# section `seeds`). Each MJX count and the seeds section run as their own process under their
# own timeout (MJX_S, SEEDS_S seconds) and write their own file, so a slow one loses only its
# own row. About 9 minutes on an H200 (2026-12-04) before the first two were added.
#
#   bash bench/gpu.sh OUTDIR   # writes OUTDIR/gpu_user_command.json, gpu_sac.json,
#                              # gpu_mjx_N.json, gpu_seeds.json, gpu.log, nvidia-smi.txt
#
# It needs a python with JAX's CUDA plugin, flax and optax (PYTHON, default python3); it runs
# from the checkout (PYTHONPATH), so nothing of ours is installed. MuJoCo and MJX, where that
# python lacks them, travel as cp312 wheels in .whl/ (ignored by git), fetched here with
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 \
#     --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux2014_x86_64 \
#     -d .whl mujoco==4.0.0 mujoco-core==4.0.0 mujoco-studio==4.0.0 mujoco-mjx==3.17.0 \
#     gymnasium==1.4.0 cloudpickle farama-notifications trimesh glfw pyopengl websockets \
#     absl-py etils
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
# The user's command, a fixed slice: `ldn-jax --env halfcheetah --algo ldn --seeds 10` (3 K, so
# 30 runs) for USER_STEPS real steps per seed and K on MJX at its default there (16 workers,
# presets.ON_MJX); its summary's env steps/s and compile seconds project the 1M-step
# command's wall clock beside the 2-core figure (docs/logs/benchmarks.md). First, with SAC's,
# as the figures not yet measured on a GPU.
PYTHONUNBUFFERED=1 timeout "${USER_S:-240}" "$python" -c \
    "import sys; from ldn_jax.host.cli import main; sys.exit(main())" \
    --env halfcheetah --algo ldn --seeds 10 --steps "${USER_STEPS:-64000}" --quiet \
    --out "$out/user-command" >>"$out/gpu.log" 2>&1 || status=$?
cp "$out/user-command/summary.json" "$out/gpu_user_command.json" 2>/dev/null || true
# SAC's update at 10 seeds (bare, in its scan, per real step through MJX): the projected wall
# clock of 200k steps at UTD 20.
PYTHONUNBUFFERED=1 timeout "${SAC_S:-150}" "$python" -m bench.bench --sections sac \
    --sac-seeds 10 --out "$out/gpu_sac.json" >>"$out/gpu.log" 2>&1 || status=$?
for seeds in 10 100 1000; do
    PYTHONUNBUFFERED=1 timeout "${MJX_S:-240}" "$python" -m bench.bench --sections mjx \
        --mjx-counts "$seeds" --out "$out/gpu_mjx_$seeds.json" >>"$out/gpu.log" 2>&1 || status=$?
    grep "^mjx " "$out/gpu.log" | tail -n 1 || true
done
PYTHONUNBUFFERED=1 timeout "${SEEDS_S:-150}" "$python" -m bench.bench --sections seeds \
    --out "$out/gpu_seeds.json" >>"$out/gpu.log" 2>&1 || status=$?
ls "$out"
exit "$status"
