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

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import envs  # noqa: E402
from experiments.runtime import compile_chunk, enable_compile_cache  # noqa: E402
from ldn_jax.config import from_preset  # noqa: E402
from ldn_jax.train import Trainer  # noqa: E402

sys.path.insert(0, str(ROOT / "bench"))
import stages  # noqa: E402

SECTIONS = (
    "env",
    "train",
    "ceiling",
    "stages",
    "sweep",
    "rejax",
    "compile",
    "scaling",
    "seeds",
    "mujoco",
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


ALGOS = ("a2c", "a2c-model", "ldn", "ppo", "ppo-model", "ppo-ldn")


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
        "ratios": _seed_ratios(rows),
    }


def _seed_ratios(rows: list[dict]) -> list[dict]:
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
    parser.add_argument("--probe", metavar="CACHE", help=argparse.SUPPRESS)
    parser.add_argument("--probe-shape", default="10x3", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.probe:
        _probe(args.probe, args.probe_shape)
        return
    default = [s for s in SECTIONS if s not in ("rejax", "mujoco")] if args.quick else SECTIONS
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
    if "sweep" in sections:
        size = dict(seeds=2, episodes=40) if args.quick else {}
        result["sweep"] = sweep_vs_separate(**size)
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


MUJOCO_TRAIN = {
    "inverted_pendulum": (ALGOS, {"seeds": 10, "episodes": 80}, ("native",)),
    "halfcheetah": (("ppo", "ldn"), {"seeds": 10, "episodes": 8}, ("native", "mjx")),
}
"""What the mujoco section trains: every algorithm on inverted_pendulum (10 seeds, 80
episodes: early, short episodes), ppo and ldn on halfcheetah on both engines (10 seeds, one
iteration of 8 x 1,000 steps each)."""

MUJOCO_ENV_TASKS = ("halfcheetah", "inverted_pendulum", "ant")
MUJOCO_ENV_SIZES = (8, 80, 640)
MUJOCO_ENV_STEPS = {"native": 100, "rollout": 100, "mjx": 20, "generalized": 20}
"""Steps per timed call: MJX is 10-50x slower on CPU, so it takes fewer to keep the section
within minutes; rates are per env step either way."""


def mujoco_section(quick: bool = False, brax_python: str | None = None) -> dict:
    """Raw env steps/s per physics path at 8 / 80 / 640 envs (native, `mujoco.rollout` from
    numpy, mjx, brax generalized when `brax_python` has brax), gymnasium's single env, how far
    native and mjx drift apart (`mujoco_drift.py`), and training steps/s: each in a fresh
    subprocess, so compiles do not pile up in one process's memory. `quick`: native and
    rollout on halfcheetah at 80 envs, ldn on inverted_pendulum."""
    here = Path(__file__).resolve().parent
    rows: dict = {"env": [], "train": [], "ratios": []}
    tasks, sizes = (("halfcheetah",), (80,)) if quick else (MUJOCO_ENV_TASKS, MUJOCO_ENV_SIZES)
    backends = ("native", "rollout") if quick else ("native", "rollout", "mjx", "generalized")
    for task in tasks:
        cmd = [str(here / "mujoco_envs.py"), "--task", task]
        rows["env"].append(
            _last_json([sys.executable, *cmd, "--backend", "gymnasium", "--steps", "2000"])
        )
        for n in sizes:
            rates = {}
            for backend in backends:
                python = sys.executable
                if backend == "generalized":
                    if not (brax_python and Path(brax_python).exists()):
                        rates[backend] = None
                        continue
                    python = brax_python
                steps = str(MUJOCO_ENV_STEPS[backend])
                args = [python, *cmd, "--backend", backend, "--envs", str(n), "--steps", steps]
                row = _last_json(args, timeout=300)
                rows["env"].append(row)
                rates[backend] = row.get("env_steps_per_second")
            rows["ratios"].append({"task": task, "envs": n, **_ratios(rates)})
    if brax_python is None or not Path(brax_python).exists():
        rows["generalized"] = "not measured: brax is not a dependency; give --brax-python"
    if not quick:
        drift = [sys.executable, str(here / "mujoco_drift.py"), "--task"]
        rows["drift"] = [_last_json([*drift, task]) for task in envs.mujoco.TASKS]
    for task, (algos, size, engines) in MUJOCO_TRAIN.items():
        if quick:
            if task != "inverted_pendulum":
                continue
            algos, size = ("ldn",), {"seeds": 1, "episodes": 8}
        for backend in engines:
            for algo in algos:
                code = (
                    f"import json, sys; sys.path.insert(0, {str(here)!r}); from bench import "
                    f"training; print(json.dumps(training({algo!r}, env={task!r}, "
                    f"chunk_iterations=1, backend={backend!r}, **{size!r})))"
                )
                rows["train"].append(_last_json([sys.executable, "-c", code]))
    rows["train_ratios"] = _train_ratios(rows["train"])
    return rows


def _ratios(rates: dict) -> dict:
    out = {}
    if rates.get("native") and rates.get("mjx"):
        out["native_over_mjx"] = round(rates["native"] / rates["mjx"], 1)
    if rates.get("native") and rates.get("generalized"):
        out["native_over_generalized"] = round(rates["native"] / rates["generalized"], 1)
    if rates.get("native") and rates.get("rollout"):
        out["rollout_over_native"] = round(rates["rollout"] / rates["native"], 2)
    return out


def _train_ratios(rows: list[dict]) -> list[dict]:
    """Training env steps/s native over mjx, per (env, algo) trained on both."""
    rate = {(r.get("env"), r.get("algo"), r.get("backend")): r.get("env_steps_per_s") for r in rows}
    out = []
    for (env, algo, backend), native in rate.items():
        mjx = rate.get((env, algo, "mjx"))
        if backend == "native" and native and mjx:
            out.append({"env": env, "algo": algo, "native_over_mjx": round(native / mjx, 1)})
    return out


def _last_json(cmd: list[str], timeout: float = 600) -> dict:
    """The last stdout line of `cmd` as JSON; a failure or a timeout is reported as a row."""
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"cmd": " ".join(cmd[1:]), "failed": f"timed out after {timeout:.0f} s"}
    if done.returncode != 0:
        return {"cmd": " ".join(cmd[1:]), "failed": done.stderr.strip().splitlines()[-1:]}
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
