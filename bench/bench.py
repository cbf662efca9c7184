"""`make bench`: throughput figures, printed as one JSON line.

Each section measures a compiled program twice: the first call's wall time minus the
second's is reported as compile seconds; the second call is the throughput measurement.
Every loop consumes what it computes, so XLA cannot delete the work being timed.
"""

from __future__ import annotations

import argparse
import json
import platform
import time

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


def training(algo: str, seeds: int = 10, episodes: int = 800, env: str = "cartpole-v1") -> dict:
    """Train from scratch (paper preset) and count real and imagined steps per wall second.

    The figure covers the whole run, the early iterations with short episodes included.
    """
    config = from_preset("paper", env=env, algo=algo, seeds=seeds, episodes=episodes)
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
        "episodes_per_seed": config.iterations * config.workers,
        "compile_s": round(compile_s, 2),
        "train_s": round(seconds, 2),
        "env_steps_per_s": round(env_steps / seconds),
        "imagined_steps_per_s": round(imagined / seconds),
        "final_moving_return_mean": round(float(states.moving_return.mean()), 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sections", default="env,train", help="comma list: env, train")
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
        result["training"] = [training(algo) for algo in ("a2c", "a2c-model", "ldn")]
    print(json.dumps(result))


if __name__ == "__main__":
    main()
