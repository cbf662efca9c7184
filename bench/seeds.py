"""`make bench` sections `scaling` and `seeds`: one compiled training program at growing
vmapped batches of seeds (and K values), timed chunk by chunk, with its memory.

`scaling` runs the `paper` preset's ldn for a short budget; `seeds` runs ldn and ppo at the
`fast` preset at 10, 100 and 1,000 seeds, the section `bench/gpu.sh` runs on a GPU.
"""

from __future__ import annotations

import sys
import time

import jax

from ldn_jax.config import from_preset
from ldn_jax.host.runtime import compile_chunk
from ldn_jax.trainer import Trainer


def seed_scaling(batches, episodes: int = 80) -> dict:
    """ldn on cartpole-v1 for a short fixed budget at several vmapped batch sizes.

    `batches` holds (seeds, number of K values). Wall seconds per chunk show how the cost
    of one compiled program grows with the batch it is vmapped over.
    """
    rows = []
    for seeds, n_k in batches:
        config = from_preset(
            "paper",
            env="cartpole-v1",
            algo="ldn",
            seeds=seeds,
            k=(0.5, 1.0, 2.0)[:n_k] if n_k > 1 else (1.0,),
            episodes=episodes,
            workers=8,
            chunk_iterations=5,
        )
        trainer = Trainer(config)
        states, k = trainer.init_batch(), trainer.k_values()
        compiled, lower_s, compile_s = compile_chunk(trainer, states, k)
        chunk_s = []
        for _ in range(config.iterations // config.chunk_iterations):
            start = time.perf_counter()
            states, _ = jax.block_until_ready(compiled(states, k))
            chunk_s.append(round(time.perf_counter() - start, 3))
        memory = compiled.memory_analysis()
        env_steps = int(states.env_steps.sum())
        rows.append(
            {
                "seeds": seeds,
                "k_values": n_k,
                "runs": seeds * n_k,
                "compile_s": round(lower_s + compile_s, 2),
                "chunk_s": chunk_s,
                "train_s": round(sum(chunk_s), 3),
                "train_s_per_run": round(sum(chunk_s) / (seeds * n_k), 4),
                "env_steps": env_steps,
                "env_steps_per_s": round(env_steps / sum(chunk_s)),
                "argument_mb": round(memory.argument_size_in_bytes / 2**20, 1),
                "temp_mb": round(memory.temp_size_in_bytes / 2**20, 1),
            }
        )
    result: dict = {"env": "cartpole-v1", "algo": "ldn", "episodes": episodes, "rows": rows}
    by_shape = {(row["seeds"], row["k_values"]): row for row in rows}
    if (10, 3) in by_shape and (1, 1) in by_shape:
        result["train_s_10x3_over_1x1"] = round(
            by_shape[10, 3]["train_s"] / by_shape[1, 1]["train_s"], 2
        )
    return result


SEED_COUNTS = (10, 100, 1000)
"""The `seeds` section's vmapped seed counts (the issue's 10, 100 and 1,000)."""


def seed_counts(
    counts=SEED_COUNTS, algos=("ldn", "ppo"), env: str = "cartpole-v1", timed: int = 2
) -> dict:
    """ldn and ppo at the `fast` preset (schedule "steps": nothing masked, so every computed
    step is a real one) at growing vmapped seed counts: env steps/s per program once it runs
    warm, what an accelerator's width buys over these cores (`bench/gpu.sh` runs this section
    on a GPU).

    Each program is compiled ahead of time, run for one warm-up iteration, then timed over
    `timed` one-iteration chunks (each worker plays the env's step limit, 500 steps on
    cartpole-v1, so a chunk is 4,000 real steps per seed). A run's steps budget covers all
    of them, so no run freezes while being timed.
    """
    rows = []
    for algo in algos:
        for seeds in counts:
            probe = from_preset("fast", env=env, algo=algo, seeds=seeds)
            per_iteration = probe.steps_per_iteration * probe.workers
            config = from_preset(
                "fast",
                env=env,
                algo=algo,
                seeds=seeds,
                steps=(1 + timed) * per_iteration,
                chunk_iterations=1,
                solved_return=None,  # throughput: no greedy evaluations, no run stops
            )
            trainer = Trainer(config)
            states, k = trainer.init_batch(), trainer.k_values()
            compiled, lower_s, compile_s = compile_chunk(trainer, states, k)
            start = time.perf_counter()
            states, _ = jax.block_until_ready(compiled(states, k))
            warm_s = time.perf_counter() - start
            before = (int(states.env_steps.sum()), int(states.imagined_steps.sum()))
            start = time.perf_counter()
            for _ in range(timed):
                states, _ = jax.block_until_ready(compiled(states, k))
            seconds = time.perf_counter() - start
            real = int(states.env_steps.sum()) - before[0]
            imagined = int(states.imagined_steps.sum()) - before[1]
            memory = compiled.memory_analysis()
            rows.append(
                {
                    "algo": algo,
                    "seeds": seeds,
                    "compile_s": round(lower_s + compile_s, 2),
                    "first_chunk_s": round(warm_s, 3),
                    "timed_s": round(seconds, 3),
                    "env_steps": real,
                    "env_steps_per_s": round(real / seconds),
                    "imagined_steps_per_s": round(imagined / seconds),
                    "argument_mb": round(memory.argument_size_in_bytes / 2**20, 1),
                    "temp_mb": round(memory.temp_size_in_bytes / 2**20, 1),
                }
            )
    return {
        "env": env,
        "preset": "fast",
        "device": jax.devices()[0].device_kind,
        "steps_per_iteration_per_seed": per_iteration,
        "timed_iterations": timed,
        "rows": rows,
        "ratios": seed_ratios(rows),
    }


def seed_ratios(rows: list[dict]) -> list[dict]:
    """Each algorithm's env steps/s at every seed count over its rate at the smallest."""
    out = []
    for algo in dict.fromkeys(row["algo"] for row in rows):
        mine = [row for row in rows if row["algo"] == algo]
        base = min(mine, key=lambda row: row["seeds"])
        for row in mine:
            out.append(
                {
                    "algo": algo,
                    "seeds": row["seeds"],
                    "env_steps_per_s_over_fewest_seeds": round(
                        row["env_steps_per_s"] / base["env_steps_per_s"], 2
                    ),
                }
            )
    return out


MJX_TARGET = 2000.0
"""The moving return whose wall time `mjx_halfcheetah` reports at its largest seed count."""


def mjx_halfcheetah(counts=SEED_COUNTS, seconds: float = 45.0, algo: str = "ppo") -> dict:
    """PPO (the default's constants) on halfcheetah through MJX at growing vmapped seed
    counts, each trained for about `seconds` of wall time after its compile: env steps/s once
    warm, compile seconds, and at the largest count the wall time until the mean moving
    return first reached `MJX_TARGET` (None if it did not within the time). `bench/gpu.sh`
    runs it on a GPU; on CPU MJX is the slow engine (docs/logs/benchmarks.md, "MuJoCo engines")."""
    rows = []
    for seeds in counts:
        config = from_preset(
            "paper", env="halfcheetah", algo=algo, seeds=seeds, backend="mjx", steps=10**9
        )
        trainer = Trainer(config)
        states, k = trainer.init_batch(), trainer.k_values()
        compiled, lower_s, compile_s = compile_chunk(trainer, states, k)
        start = time.perf_counter()
        states, _ = jax.block_until_ready(compiled(states, k))
        first_s = time.perf_counter() - start
        steps_before, elapsed, reached, curve = int(states.env_steps.sum()), 0.0, None, []
        while elapsed < seconds:
            tick = time.perf_counter()
            states, _ = jax.block_until_ready(compiled(states, k))
            elapsed += time.perf_counter() - tick
            moving = float(jax.numpy.nanmean(states.moving_return))
            curve.append((round(first_s + elapsed, 2), int(states.env_steps[0, 0]), moving))
            if reached is None and moving >= MJX_TARGET:
                reached = round(first_s + elapsed, 2)
        real = int(states.env_steps.sum()) - steps_before
        rows.append(
            {
                "seeds": seeds,
                "compile_s": round(lower_s + compile_s, 2),
                "first_chunk_s": round(first_s, 3),
                "timed_s": round(elapsed, 3),
                "env_steps_per_s": round(real / elapsed),
                "env_steps_per_seed": int(states.env_steps[0, 0]),
                "final_mean_moving_return": round(curve[-1][2], 1),
                "seconds_to_target": reached,
                "curve": curve,
            }
        )
        row = rows[-1]
        print(
            f"mjx halfcheetah {algo}, {seeds} seeds: compile {row['compile_s']} s, "
            f"{row['env_steps_per_s']:,} env steps/s, moving return "
            f"{row['final_mean_moving_return']} at {row['env_steps_per_seed']:,} steps per seed",
            file=sys.stderr,
            flush=True,
        )
    return {
        "env": "halfcheetah",
        "backend": "mjx",
        "algo": algo,
        "device": jax.devices()[0].device_kind,
        "target_moving_return": MJX_TARGET,
        "rows": rows,
    }
