"""`make bench`: throughput figures, printed as one JSON line.

Each section measures a compiled program twice: the first call's wall time minus the
second's is reported as compile seconds; the second call is the throughput measurement.
Every loop consumes what it computes, so XLA cannot delete the work being timed.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp

import envs
from ldn_jax.config import from_preset
from ldn_jax.train import Trainer


def _timed(fn, *args):
    start = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    return out, time.perf_counter() - start


def _median_seconds(fn, repeats: int = 3) -> tuple[float, float]:
    """Return (compile seconds, median run seconds) of a jitted `fn(key)`."""
    _, first = _timed(fn, jax.random.key(0))
    runs = sorted(_timed(fn, jax.random.key(i + 1))[1] for i in range(repeats))
    median = runs[len(runs) // 2]
    return max(first - median, 0.0), median


def cartpole_env_steps(n_envs: int, auto_reset: bool, steps: int = 1000) -> dict:
    """Random-action CartPole-v1 under `lax.scan`, vmapped over `n_envs`.

    With `auto_reset`, finished envs restart from a fresh state drawn in one batched call
    (what a continuing-rollout trainer needs); without, envs just keep stepping (what our
    episode-synchronous trainer runs: it masks finished workers instead of resetting them).
    """
    env, params = envs.make("cartpole-v1")
    step = jax.vmap(env.step, (None, 0, 0, None))

    def run(key):
        _, state = jax.vmap(env.reset, (0, None))(jax.random.split(key, n_envs), params)

        def body(carry, key):
            state, total = carry
            k_act, k_step, k_reset = jax.random.split(key, 3)
            actions = jax.random.randint(k_act, (n_envs,), 0, 2)
            obs, state, reward, terminated, truncated, _ = step(k_step, state, actions, params)
            if auto_reset:
                done = terminated | truncated
                fresh = jax.random.uniform(k_reset, (n_envs, 4), jnp.float32, -0.05, 0.05)
                state = state.replace(
                    physics=jnp.where(done[:, None], fresh, state.physics),
                    time=jnp.where(done, 0, state.time),
                )
            return (state, total + reward.sum() + obs.sum()), None

        (_, total), _ = jax.lax.scan(body, (state, 0.0), jax.random.split(key, steps))
        return total

    compile_s, run_s = _median_seconds(jax.jit(run))
    return {
        "n_envs": n_envs,
        "auto_reset": auto_reset,
        "steps_per_s": round(n_envs * steps / run_s),
        "compile_s": round(compile_s, 3),
    }


def training(
    algo: str,
    seeds: int = 10,
    episodes: int = 800,
    env: str = "cartpole-v1",
    workers: int = 8,
    chunk_iterations: int = 5,
) -> dict:
    """Train from scratch (paper preset) and count real and imagined steps per wall second.

    The figure covers the whole run, the early iterations with short episodes included.
    """
    config = from_preset(
        "paper",
        env=env,
        algo=algo,
        seeds=seeds,
        episodes=episodes,
        workers=workers,
        chunk_iterations=chunk_iterations,
    )
    trainer = Trainer(config)
    states, k = trainer.init_batch(), trainer.k_values()
    start = time.perf_counter()
    chunk = trainer.batched_chunk().lower(states, k).compile()
    compile_s = time.perf_counter() - start
    start = time.perf_counter()
    for _ in range(config.iterations // config.chunk_iterations):
        states, _ = chunk(states, k)
    jax.block_until_ready(states)
    seconds = time.perf_counter() - start
    env_steps = int(states.env_steps.sum())
    imagined = int(states.imagined_steps.sum())
    return {
        "algo": algo,
        "env": env,
        "seeds": seeds,
        "workers": workers,
        "env_steps": env_steps,
        "episodes_per_seed": config.iterations * config.workers,
        "compile_s": round(compile_s, 2),
        "train_s": round(seconds, 2),
        "env_steps_per_s": round(env_steps / seconds),
        "imagined_steps_per_s": round(imagined / seconds),
        "final_moving_return_mean": round(float(states.moving_return.mean()), 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument(
        "--sections",
        default="env,train,rejax,mujoco",
        help="comma list: env, train, rejax, mujoco",
    )
    parser.add_argument(
        "--anchor-python",
        default=os.environ.get(
            "ANCHOR_PY", str(Path.home() / ".cache/ldn-anchors/venv/bin/python")
        ),
        help="python of the anchors' venv (shared/anchors/README.md), for side-by-side rows",
    )
    args = parser.parse_args()
    sections = set(args.sections.split(","))
    result: dict = {
        "jax": jax.__version__,
        "backend": jax.default_backend(),
        "machine": platform.machine(),
    }
    if "env" in sections:
        result["cartpole_env"] = [
            cartpole_env_steps(n, auto_reset)
            for auto_reset in (False, True)
            for n in (1, 64, 1024, 8192)
        ]
    if "train" in sections:
        result["training"] = [
            training(algo) for algo in ("a2c", "a2c-model", "ldn", "ppo", "ppo-model", "ppo-ldn")
        ]
        _add_overheads(result["training"])
    if "mujoco" in sections:
        result["mujoco"] = mujoco_section()
    if "rejax" in sections:
        result["ppo_vs_rejax"] = ppo_vs_rejax(args.anchor_python)
    print(json.dumps(result))


def mujoco_section() -> dict:
    """MJX (and brax generalized) env steps/s at 64 envs, and ldn training steps/s, for
    inverted_pendulum and halfcheetah: each in a fresh subprocess, so compiles do not pile up
    in one process's memory."""
    here = Path(__file__).resolve().parent
    rows: dict = {"env": [], "train": []}
    for task in ("inverted_pendulum", "halfcheetah"):
        for backend in ("mjx", "generalized"):
            cmd = [sys.executable, str(here / "mujoco_envs.py"), "--task", task]
            rows["env"].append(_last_json([*cmd, "--backend", backend, "--envs", "64"]))
        code = (
            f"import json, sys; sys.path.insert(0, {str(here)!r}); from bench import training; "
            f"print(json.dumps(training('ldn', seeds=1, episodes=8, env={task!r}, "
            "chunk_iterations=1)))"
        )
        rows["train"].append(_last_json([sys.executable, "-c", code]))
    return rows


def _last_json(cmd: list[str]) -> dict:
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        return {"cmd": " ".join(cmd[1:3]), "failed": done.stderr.strip().splitlines()[-1:]}
    return json.loads(done.stdout.strip().splitlines()[-1])


def _add_overheads(rows: list[dict]) -> None:
    """Wall seconds per real env step of each -model / -ldn variant over its plain learner's.

    This is the cost of the model and imagination stages, reported apart from the learner's.
    """
    plain = {row["algo"]: row for row in rows if row["algo"] in ("a2c", "ppo")}
    for row in rows:
        base = plain["ppo" if row["algo"].startswith("ppo") else "a2c"]
        row["seconds_per_env_step_vs_plain"] = round(
            base["env_steps_per_s"] / max(row["env_steps_per_s"], 1), 2
        )


def ppo_vs_rejax(anchor_python: str) -> dict:
    """Plain ppo at rejax's CartPole batch shape (1 seed, 5 workers, 100-step rollouts,
    5 epochs x 5 minibatches, about 100k env steps), next to rejax measured in the same run.

    rejax runs in its own venv (see shared/anchors/README.md); without it only ours is given.
    """
    # 480 episodes of 5 workers took 98,845 env steps from scratch (seed 0): rejax's 100k.
    ours = training("ppo", seeds=1, episodes=480, workers=5, chunk_iterations=96)
    out: dict = {"ours": ours}
    script = Path(__file__).resolve().parents[1].parent / "shared/anchors/rejax_bench.py"
    if not (Path(anchor_python).exists() and script.exists()):
        out["rejax"] = f"not measured: needs {anchor_python} and {script}"
        return out
    cmd = [anchor_python, str(script), "--num-seeds", "1", "--repeats", "3"]
    done = subprocess.run([*cmd, "--mode", "throughput"], capture_output=True, text=True)
    if done.returncode != 0:
        out["rejax"] = f"failed: {done.stderr.strip().splitlines()[-1:]}"
        return out
    rejax = json.loads(done.stdout.strip().splitlines()[-1])
    out["rejax"] = {key: rejax[key] for key in ("steps_per_s_total", "compile_s", "num_envs")}
    out["ours_over_rejax_steps_per_s"] = round(
        ours["env_steps_per_s"] / rejax["steps_per_s_total"], 2
    )
    return out


if __name__ == "__main__":
    main()
