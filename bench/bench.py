"""`make bench`: throughput, compile cost, memory and seed scaling, as one JSON document
(printed, and written to --out).

Each env section measures a compiled program twice: the first call's wall time minus the
second's is reported as compile seconds; the second call is the throughput measurement.
Every loop consumes what it computes, so XLA cannot delete the work being timed. Training
sections compile ahead of time and report compile and train seconds apart. This process
uses no persistent compilation cache, so its compile seconds are cold ones; the `compile`
section measures the cache in fresh processes.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax
import jax.numpy as jnp

from bench import stages
from bench.mujoco_section import mujoco_section
from bench.sac import sac_costs
from bench.seeds import SEED_COUNTS, seed_counts, seed_scaling
from bench.seeds import mjx_halfcheetah as seed_counts_mjx
from bench.stages import ALGOS
from ldn_jax import envs
from ldn_jax.config import from_preset
from ldn_jax.host.runtime import compile_chunk, enable_compile_cache
from ldn_jax.trainer import Trainer

ROOT = Path(__file__).resolve().parents[1]

SECTIONS = (
    "env",
    "train",
    "ceiling",
    "stages",
    "branched",
    "sac",
    "sweep",
    "rejax",
    "compile",
    "scaling",
    "seeds",
    "mujoco",
    "mjx",
)


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
    backend: str = "auto",
    schedule: str = "episodes",
    steps: int | None = None,
) -> dict:
    """Train from scratch (paper preset) and count real and imagined steps per wall second.

    The figure covers the whole run, the early iterations with short episodes included.
    `schedule` "steps" takes a `steps` budget (the real steps of the "episodes" run of the
    same algorithm, so that both cover the same experience).
    """
    config = from_preset(
        "paper",
        env=env,
        algo=algo,
        seeds=seeds,
        k=(1.0,),
        episodes=episodes,
        steps=steps,
        workers=workers,
        chunk_iterations=chunk_iterations,
        backend=backend,
        schedule=schedule,
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
        "schedule": schedule,
        "env": env,
        "backend": trainer.env_params.backend if env in envs.mujoco.TASKS else None,
        "seeds": seeds,
        "workers": workers,
        "env_steps": env_steps,
        "episodes_per_seed": round(int(states.episodes.sum()) / seeds),
        "compile_s": round(compile_s, 2),
        "train_s": round(seconds, 2),
        "env_steps_per_s": round(env_steps / seconds),
        "imagined_steps_per_s": round(imagined / seconds),
        "final_moving_return_mean": round(float(states.moving_return.mean()), 1),
    }


def both_schedules(size: dict) -> list[dict]:
    """`training` of every algorithm under schedule "episodes", then under "steps" over the
    same real steps per seed."""
    rows = [training(algo, **size) for algo in ALGOS]
    for row in list(rows):
        steps = row["env_steps"] // row["seeds"]
        rows.append(training(row["algo"], **size, schedule="steps", steps=steps))
    return rows


SWEEP_GRID = (
    ("agent.actor_lr", (3e-4, 1e-3, 3e-3)),
    ("agent.critic_lr", (3e-4, 1e-3, 3e-3)),
)
"""The `sweep` section's 3 x 3 grid."""


def sweep_vs_separate(seeds: int = 10, episodes: int = 400, algo: str = "a2c") -> dict:
    """A 3 x 3 sweep x `seeds` as one vmapped program against the 9 runs it replaces, one
    after another, each on cartpole-v1; wall seconds including compile (no persistent cache
    in this process), measured in the same process one after the other."""
    config = from_preset(
        "paper", env="cartpole-v1", algo=algo, seeds=seeds, episodes=episodes, sweep=SWEEP_GRID
    )

    def run(config) -> tuple[float, float]:
        start = time.perf_counter()
        trainer = Trainer(config)
        states = trainer.init_batch()
        chunk = trainer.batched_chunk().lower(states, trainer.point_values()).compile()
        compiled = time.perf_counter()
        for _ in range(config.iterations // config.chunk_iterations):
            states, metrics = chunk(states, trainer.point_values())
        jax.block_until_ready(metrics["moving_return"])
        return compiled - start, time.perf_counter() - start

    sweep_compile, sweep_total = run(config)
    separate = [run(config.at_point(i)) for i in range(len(config.points))]
    separate_total = sum(total for _, total in separate)
    return {
        "env": config.env,
        "algo": algo,
        "grid": {name: list(values) for name, values in SWEEP_GRID},
        "seeds": seeds,
        "episodes": episodes,
        "sweep_seconds": round(sweep_total, 2),
        "sweep_compile_seconds": round(sweep_compile, 2),
        "separate_seconds": round(separate_total, 2),
        "separate_compile_seconds": round(sum(c for c, _ in separate), 2),
        "speedup": round(separate_total / sweep_total, 2),
    }


def compile_cold_warm(seeds: int, n_k: int) -> dict:
    """The same training program compiled in two fresh processes sharing an empty persistent
    cache: the first compiles (cold), the second loads it (warm)."""
    runs = {}
    with tempfile.TemporaryDirectory() as cache:
        command = [sys.executable, __file__, "--probe", cache, "--probe-shape", f"{seeds}x{n_k}"]
        for name in ("cold", "warm"):
            start = time.perf_counter()
            done = subprocess.run(command, capture_output=True, text=True, check=True)
            runs[name] = json.loads(done.stdout.strip().splitlines()[-1])
            runs[name]["process_s"] = round(time.perf_counter() - start, 2)
    return {
        "program": f"ldn cartpole-v1 chunk, {seeds} seeds x {n_k} K",
        **runs,
        "warm_over_cold_compile": round(runs["warm"]["compile_s"] / runs["cold"]["compile_s"], 3),
    }


def _probe(cache: str, shape: str) -> None:
    """Inside a fresh process: what a training run pays before its first chunk."""
    start = time.perf_counter()
    enable_compile_cache(cache)
    seeds, n_k = (int(v) for v in shape.split("x"))
    k = (0.5, 1.0, 2.0)[:n_k] if n_k > 1 else (1.0,)
    config = from_preset("paper", env="cartpole-v1", algo="ldn", seeds=seeds, k=k, episodes=80)
    trainer = Trainer(config)
    states = jax.block_until_ready(trainer.init_batch())
    init_s = time.perf_counter() - start
    compiled, lower_s, compile_s = compile_chunk(trainer, states, trainer.k_values())
    memory = compiled.memory_analysis()
    row = {
        "init_s": round(init_s, 2),
        "lower_s": round(lower_s, 2),
        "xla_compile_s": round(compile_s, 2),
        "compile_s": round(lower_s + compile_s, 2),
        "peak_rss_mb": round(_peak_rss_mb()),
        "program_argument_mb": round(memory.argument_size_in_bytes / 2**20, 1),
        "program_output_mb": round(memory.output_size_in_bytes / 2**20, 1),
        "program_temp_mb": round(memory.temp_size_in_bytes / 2**20, 1),
    }
    print(json.dumps(row))


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sections", help=f"comma list of {', '.join(SECTIONS)} (default all)")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="smaller sizes (a few minutes); without rejax unless --sections names it",
    )
    parser.add_argument(
        "--out", default=str(ROOT / "bench" / "results.json"), help="also write the JSON here"
    )
    parser.add_argument(
        "--anchor-python",
        default=os.environ.get(
            "ANCHOR_PY", str(Path.home() / ".cache/ldn-anchors/venv/bin/python")
        ),
        help="python of the anchors' venv (shared/anchors/README.md), for side-by-side rows",
    )
    parser.add_argument(
        "--brax-python",
        default=os.environ.get("BRAX_PYTHON"),
        help="a python with brax 0.14, for the mujoco section's brax-generalized rows",
    )
    parser.add_argument(
        "--seed-counts",
        type=lambda text: tuple(int(v) for v in text.split(",")),
        help="section seeds: the vmapped seed counts, e.g. 10,100 (default 10,100,1000; "
        "--quick 10,100)",
    )
    parser.add_argument(
        "--mjx-counts",
        type=lambda text: tuple(int(v) for v in text.split(",")),
        help="section mjx: the vmapped seed counts (default 10,100,1000; --quick 1)",
    )
    parser.add_argument(
        "--sac-seeds",
        type=int,
        help="section sac: the vmapped seeds (default 5; --quick 1)",
    )
    parser.add_argument("--probe", metavar="CACHE", help=argparse.SUPPRESS)
    parser.add_argument("--probe-shape", default="10x3", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.probe:
        _probe(args.probe, args.probe_shape)
        return
    slow = ("rejax", "mujoco", "mjx")  # the anchors' venv, MuJoCo's long runs, a GPU's section
    default = [s for s in SECTIONS if s not in slow] if args.quick else SECTIONS[:-1]
    sections = set(args.sections.split(",") if args.sections else default)
    result: dict = {
        "jax": jax.__version__,
        "backend": jax.default_backend(),
        "device_kind": jax.devices()[0].device_kind,
        "devices": jax.device_count(),
        "cpus": os.cpu_count(),
        "machine": platform.machine(),
        "quick": args.quick,
    }
    if "env" in sections:
        result["cartpole_env"] = [
            cartpole_env_steps(n, auto_reset)
            for auto_reset in (False, True)
            for n in ((1, 1024) if args.quick else (1, 64, 1024, 8192))
        ]
    train_size = dict(seeds=2, episodes=160) if args.quick else {}
    if "train" in sections:
        result["training"] = both_schedules(train_size)
        for schedule in ("episodes", "steps"):
            _add_overheads([r for r in result["training"] if r["schedule"] == schedule])
    if "ceiling" in sections:
        size = dict(seeds=2, segments=200) if args.quick else {}
        top = stages.ceiling(**size)
        rows = result.get("training") or both_schedules(train_size)
        result["ceiling"] = {**top, "ratios": stages.ratios_to_ceiling(rows, top)}
        update = stages.ppo_update(seeds=size.get("seeds", 10))
        update["update_only_over_ceiling"] = round(
            update["update_only_env_steps_per_s"] / top["env_steps_per_s"], 3
        )
        result["ceiling"]["ppo_update"] = update
    if "stages" in sections:
        size = dict(runs=6, warm_episodes=80) if args.quick else {}
        result["stages"] = [stages.stages(algo, **size) for algo in ALGOS]
    if "branched" in sections:
        size = dict(seeds=1, warm_iterations=2) if args.quick else {}
        result["branched_stages"] = stages.branched_stages(**size)
    if "sac" in sections:
        size = dict(seeds=1, steps=1000) if args.quick else {}
        if args.sac_seeds:
            size["seeds"] = args.sac_seeds
        result["sac"] = sac_costs(**size)
    if "sweep" in sections:
        size = dict(seeds=2, episodes=40) if args.quick else {}
        result["sweep"] = sweep_vs_separate(**size)
    if "mjx" in sections:
        size = dict(counts=(1,), seconds=5.0) if args.quick else {}
        if args.mjx_counts:
            size["counts"] = args.mjx_counts
        result["mjx_halfcheetah"] = seed_counts_mjx(**size)
    if "mujoco" in sections:
        result["mujoco"] = mujoco_section(args.quick, args.brax_python)
    if "rejax" in sections:
        result["ppo_vs_rejax"] = ppo_vs_rejax(args.anchor_python)
    if "compile" in sections:
        result["compile_cache"] = compile_cold_warm(*((1, 1) if args.quick else (10, 3)))
    if "scaling" in sections:
        batches = [(1, 1), (10, 1), (10, 3)] + ([] if args.quick else [(100, 1)])
        result["seed_scaling"] = seed_scaling(batches)
    if "seeds" in sections:
        counts = args.seed_counts or ((10, 100) if args.quick else SEED_COUNTS)
        result["seed_counts"] = seed_counts(counts)
    result["peak_rss_mb"] = round(_peak_rss_mb())
    text = json.dumps(result, indent=1)
    print(text)
    Path(args.out).write_text(text + "\n")


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
