"""Env steps per second of MuJoCo tasks per brax backend, printed as one JSON line per run.

`python bench/mujoco_envs.py --task halfcheetah --backend mjx`: jit(vmap) of a `--steps` scan
over `--envs` envs with uniform random actions. Every observation is summed into the carry, so
XLA cannot delete the physics. Compile seconds: first call minus the median of the rest.
"""

from __future__ import annotations

import argparse
import json
import time

import jax
import jax.numpy as jnp

import envs


def make_rollout(task: str, backend: str, steps: int):
    env, params = envs.make(task)
    params = params.replace(backend=backend)
    size = env.action_spec(params).size

    def rollout(key):
        key, k_reset = jax.random.split(key)
        obs, state = env.reset(k_reset, params)

        def body(carry, key):
            state, total = carry
            k_act, k_step = jax.random.split(key)
            action = jax.random.uniform(k_act, (size,), minval=-1.0, maxval=1.0)
            obs, state, *_ = env.step(k_step, state, action, params)
            return (state, total + jnp.sum(obs)), None

        (_, total), _ = jax.lax.scan(body, (state, jnp.sum(obs)), jax.random.split(key, steps))
        return total

    return rollout


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="inverted_pendulum")
    parser.add_argument("--backend", default="mjx")
    parser.add_argument("--envs", type=int, default=64)
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    fn = jax.jit(jax.vmap(make_rollout(args.task, args.backend, args.steps)))

    def timed(seed: int) -> float:
        keys = jax.random.split(jax.random.key(seed), args.envs)
        start = time.perf_counter()
        jax.block_until_ready(fn(keys))
        return time.perf_counter() - start

    first = timed(0)
    runs = sorted(timed(seed) for seed in range(1, args.repeats + 1))
    median = runs[len(runs) // 2]
    result = {
        "task": args.task,
        "backend": args.backend,
        "envs": args.envs,
        "steps": args.steps,
        "device": jax.devices()[0].platform,
        "compile_seconds": round(first - median, 1),
        "env_steps_per_second": round(args.envs * args.steps / median),
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
