"""Env steps per second of a MuJoCo task on one physics path, printed as one JSON line.

    python -m bench.mujoco_envs --task halfcheetah --backend native --envs 80

Backends:
- `native`, `mjx`: our env (`ldn_jax.envs.make(task)`), jit(vmap) of a `--steps` scan over `--envs`
  envs with uniform random actions; every observation and reward is summed into the carry,
  so XLA cannot delete the physics. Compile seconds: first call minus the median of the rest.
- `rollout`: `mujoco.rollout` called from numpy on the same model with the same pool as the
  native engine, no JAX: what the native engine's callback costs on top is the difference.
- `gymnasium`: gymnasium's own env, one env stepped from Python: the reference a user knows.
- `generalized`: brax's generalized pipeline (brax's own, slightly different, model). brax is
  not a dependency of this project: run this one with a Python that has brax 0.14.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def _median(times: list[float]) -> float:
    return sorted(times)[len(times) // 2]


def jax_rate(task: str, backend: str, n_envs: int, steps: int, repeats: int) -> dict:
    import jax

    from ldn_jax import envs

    env, params = envs.make(task)
    params = params.replace(backend=backend)
    size = env.action_spec(params).size

    def rollout(key):
        key, k_reset = jax.random.split(key)
        obs, state = env.reset(k_reset, params)

        def body(carry, key):
            state, total = carry
            action = jax.random.uniform(key, (size,), minval=-1.0, maxval=1.0)
            obs, state, reward, *_ = env.step(key, state, action, params)
            return (state, total + obs.sum() + reward), None

        return jax.lax.scan(body, (state, obs.sum()), jax.random.split(key, steps))[0][1]

    fn = jax.jit(jax.vmap(rollout))

    def timed(seed: int) -> float:
        keys = jax.random.split(jax.random.key(seed), n_envs)
        start = time.perf_counter()
        jax.block_until_ready(fn(keys))
        return time.perf_counter() - start

    first = timed(0)
    median = _median([timed(seed) for seed in range(1, repeats + 1)])
    return {"compile_seconds": round(max(first - median, 0.0), 1), "seconds": median}


def rollout_rate(task: str, n_envs: int, steps: int, repeats: int) -> dict:
    import mujoco

    from ldn_jax.envs.mujoco import TASKS, model, native

    t = TASKS[task]
    m = model.load(t.asset)
    datas = [mujoco.MjData(m) for _ in range(native.threads())]
    pool = native._pool().rollout
    data = mujoco.MjData(m)
    mujoco.mj_forward(m, data)
    state = np.zeros((n_envs, model.state_size(m)))
    mujoco.mj_getState(m, data, state[0], mujoco.mjtState.mjSTATE_FULLPHYSICS)
    state[:] = state[0]
    rng = np.random.default_rng(0)
    low, high = t.ctrl_range

    def run() -> float:
        nonlocal state
        start = time.perf_counter()
        for _ in range(steps):
            ctrl = rng.uniform(low, high, (n_envs, 1, m.nu))
            out, _ = pool.rollout(m, datas, state, ctrl, nstep=t.frame_skip)
            state = out[:, -1]
        return time.perf_counter() - start

    run()
    return {"seconds": _median([run() for _ in range(repeats)])}


def gymnasium_rate(task: str, steps: int, repeats: int) -> dict:
    import gymnasium

    from ldn_jax.envs.mujoco import TASKS, model

    with model.settotalmass_ignored():
        env = gymnasium.make(TASKS[task].gymnasium_id).unwrapped  # no per-step checkers
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    low, high = env.action_space.low, env.action_space.high

    def run() -> float:
        start = time.perf_counter()
        for _ in range(steps):
            _, _, terminated, _, _ = env.step(rng.uniform(low, high))
            if terminated:
                env.reset()
        return time.perf_counter() - start

    run()
    return {"seconds": _median([run() for _ in range(repeats)])}


def brax_rate(task: str, n_envs: int, steps: int, repeats: int) -> dict:
    import warnings

    warnings.filterwarnings("ignore")
    import jax
    from brax import envs as brax_envs

    env = brax_envs.get_environment(task, backend="generalized")

    def rollout(key):
        state = env.reset(key)

        def body(carry, key):
            state, total = carry
            action = jax.random.uniform(key, (env.action_size,), minval=-1.0, maxval=1.0)
            state = env.step(state, action)
            return (state, total + state.obs.sum()), None

        return jax.lax.scan(body, (state, 0.0), jax.random.split(key, steps))[0][1]

    fn = jax.jit(jax.vmap(rollout))

    def timed(seed: int) -> float:
        start = time.perf_counter()
        jax.block_until_ready(fn(jax.random.split(jax.random.key(seed), n_envs)))
        return time.perf_counter() - start

    first = timed(0)
    median = _median([timed(seed) for seed in range(1, repeats + 1)])
    return {"compile_seconds": round(max(first - median, 0.0), 1), "seconds": median}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="inverted_pendulum")
    parser.add_argument(
        "--backend",
        default="native",
        choices=("native", "mjx", "rollout", "gymnasium", "generalized"),
    )
    parser.add_argument("--envs", type=int, default=80)
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    if args.backend in ("native", "mjx"):
        out = jax_rate(args.task, args.backend, args.envs, args.steps, args.repeats)
    elif args.backend == "rollout":
        out = rollout_rate(args.task, args.envs, args.steps, args.repeats)
    elif args.backend == "gymnasium":
        args.envs = 1
        out = gymnasium_rate(args.task, args.steps, args.repeats)
    else:
        out = brax_rate(args.task, args.envs, args.steps, args.repeats)
    seconds = out.pop("seconds")
    result = {
        "task": args.task,
        "backend": args.backend,
        "envs": args.envs,
        "steps": args.steps,
        **out,
        "env_steps_per_second": round(args.envs * args.steps / seconds),
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
