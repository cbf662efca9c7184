"""What the paper scripts share: scales, the configs of their runs, the paper's numbers,
statistics and result files (the runs themselves: `experiments.paper.cache`).

Every script takes `--scale cpu|cpu-full|paper` (default cpu), `--smoke` (a tiny budget, for
tests) and `--results DIR` (default experiments/results), and writes into `DIR/<its name>/`.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ldn_jax.config import Config, from_preset, validate
from ldn_jax.host import stats
from ldn_jax.host.run_dir import RunDirBusy

ROOT = Path(__file__).resolve().parents[2]

RESULTS = ROOT / "experiments" / "results"


@dataclass(frozen=True)
class Scale:
    """How big the reproduction runs are."""

    name: str
    seeds: int
    """Seeds per run (the paper: 10 runs per result)."""
    episodes: int
    """Real episodes per seed (summed over workers)."""
    workers: int
    chunk_iterations: int
    cartpole_envs: tuple[str, ...]
    """The CartPole versions of Tables 2 and 3 and Figure 4."""
    ld_env: str
    """The env of the LD studies (Figures 5 and 9, calibration): the paper's cartpole-v2."""
    calibration_points: tuple[int, ...]
    """Episodes after which the LD calibration study analyses the model; the last is the
    Table 2 run's final checkpoint."""
    calibration_episodes: int
    """Imagined episodes per seed in each calibration analysis."""
    ensemble_members: int
    """E: models of the ensemble-disagreement learning degree in the calibration study."""
    mujoco_seeds: int = 0
    """Seeds per MuJoCo run (Tables 4 and 5, Figure 9's MuJoCo panels)."""
    mujoco_budgets: dict[str, dict[str, int]] = field(default_factory=dict)
    """Each MuJoCo task this scale runs -> its budget per seed, `{"steps": N}` (real env
    steps, summed over workers) or `{"episodes": N}`; the tasks left out are reported as
    pending."""
    ablation_envs: tuple[str, ...] = ()
    """Figure 9's panels besides `ld_env` (the K ablation on MuJoCo tasks)."""
    learning_envs: tuple[str, ...] = ()
    """The MuJoCo tasks whose budget here is long enough to learn in; the others are short
    pipeline runs, which Table 5 (episodes to the top) leaves pending."""


CARTPOLE = ("cartpole-v0", "cartpole-v1", "cartpole-v2")

MUJOCO = ("ant", "halfcheetah", "hopper", "reacher", "walker2d", "inverted_pendulum")

PAPER_STEP_LIMIT = 1000
"""The paper's episodes: 1,000 steps on every MuJoCo task, reacher's too."""

MUJOCO_CPU_SEEDS = 5
MUJOCO_CPU_BUDGETS = {
    "inverted_pendulum": {"steps": 300_000},
    "halfcheetah": {"steps": 200_000},
    "reacher": {"steps": 100_000},
    "hopper": {"episodes": 400},
    "walker2d": {"episodes": 400},
    "ant": {"episodes": 80},
}
"""The CPU scale's MuJoCo budgets per seed, sized to what the native engine does on these 2
cores: short runs that compare the algorithms early in learning, so that all six tasks of
Tables 4 and 5 and Figure 9 run (REPORT.md gives the measured time; a task's README figures
use its longer default `--steps`). Where episodes end early (hopper, walker2d, ant), a step
budget ends only once the seed with the shortest episodes has its steps, while every
iteration waits for the longest episode of the batch (the trainer-speed issue's lockstep
waste): ant's a2c-model took 421 s for 31 iterations, its seeds at 17k-70k of 100k steps,
so those three tasks are budgeted in episodes here."""

SCALES = {
    # Tests: a tiny budget on one CartPole version and inverted_pendulum (compiling
    # dominates), every code path.
    "smoke": Scale(
        "smoke",
        2,
        16,
        4,
        2,
        ("cartpole-v0",),
        "cartpole-v0",
        (8, 16),
        4,
        2,
        mujoco_seeds=2,
        mujoco_budgets={"inverted_pendulum": {"episodes": 8}},
        ablation_envs=("inverted_pendulum",),
        learning_envs=("inverted_pendulum",),
    ),
    # The default: the paper's 10 seeds with a budget most runs cross within (episodes to
    # threshold measured on these 2 cores: a2c ~900-1300, a2c-model ~450-610, ldn ~850-1150).
    # MuJoCo: every task, at the budgets of `MUJOCO_CPU_BUDGETS`.
    "cpu": Scale(
        "cpu",
        10,
        2000,
        8,
        5,
        CARTPOLE,
        "cartpole-v2",
        (200, 800, 2000),
        32,
        5,
        mujoco_seeds=MUJOCO_CPU_SEEDS,
        mujoco_budgets=MUJOCO_CPU_BUDGETS,
        ablation_envs=MUJOCO,
        learning_envs=MUJOCO,
    ),
    # A budget every run should cross within, larger calibration samples, and every MuJoCo
    # task at the episodes of the paper's Table 5 and beyond (meant for a GPU).
    "paper": Scale(
        "paper",
        10,
        4000,
        8,
        5,
        CARTPOLE,
        "cartpole-v2",
        (200, 800, 2000, 4000),
        128,
        10,
        mujoco_seeds=10,
        mujoco_budgets={env: {"episodes": 4000} for env in MUJOCO},
        ablation_envs=MUJOCO,
        learning_envs=MUJOCO,
    ),
}

# The CPU scale's CartPole studies with every MuJoCo result at 1M env steps per run, the
# budget MuJoCo results are quoted at (Tables 4 and 5, Figure 9): hours on 2 cores, each run
# cached and an interrupted `make paper SCALE=cpu-full` resumed where it stopped.
SCALES["cpu-full"] = replace(
    SCALES["cpu"], name="cpu-full", mujoco_budgets={env: {"steps": 1_000_000} for env in MUJOCO}
)


def parse_args(argv: list[str] | None, description: str) -> tuple[Scale, Path]:
    p = argparse.ArgumentParser(
        description=description, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument(
        "--scale", choices=("cpu", "cpu-full", "paper"), default="cpu", help="default: cpu"
    )
    p.add_argument("--smoke", action="store_true", help="tiny budget (tests); overrides --scale")
    p.add_argument("--results", type=Path, default=RESULTS, help=f"default: {RESULTS}")
    args = p.parse_args(argv)
    compile_cache(args.results)
    return SCALES["smoke" if args.smoke else args.scale], args.results


def take_flag(argv: list[str] | None, flag: str) -> tuple[bool, list[str]]:
    """Whether `flag` is among a script's arguments (the command line's where `argv` is None),
    and the arguments without it, for `parse_args`."""
    argv = sys.argv[1:] if argv is None else list(argv)
    return flag in argv, [a for a in argv if a != flag]


def script(main: Callable[[list[str] | None], int]) -> int:
    """A script's exit status from the command line: a run that another process is training
    (`plan --train`, a study) stops the script with one line, as `ldn-jax --resume` does."""
    try:
        return main(None)
    except RunDirBusy as busy:
        print(f"error: {busy}", file=sys.stderr)
        return 2


def compile_cache(results: Path) -> None:
    """JAX's persistent compilation cache under the runs: the scripts compile the same
    training programs again (calibration.py retrains the cartpole-v2 ldn run in-process)."""
    import jax

    jax.config.update("jax_compilation_cache_dir", str(results / "runs" / "jax-cache"))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


# -- the paper's numbers (docs/paper.md) -----------------------------------------------------------

PAPER_ALGOS = {
    "a2c": "A3C",
    "a2c-model": "A3C-Model",
    "ldn": "MBRL-LDN",
    "ppo": "PPO2",
    "ppo-model": "PPO2-Model",
    "ppo-ldn": "PPO2-LDN",
}
"""Our algorithm names -> the paper's (A2C is our synchronous A3C)."""

PAPER_TABLE2 = {
    ("a2c", "cartpole-v0"): (346.4, 44.5),
    ("a2c", "cartpole-v1"): (296.5, 46.7),
    ("a2c", "cartpole-v2"): (380.8, 22.7),
    ("a2c-model", "cartpole-v0"): (286.1, 53.4),
    ("a2c-model", "cartpole-v1"): (280.6, 61.1),
    ("a2c-model", "cartpole-v2"): (259.8, 35.7),
    ("ldn", "cartpole-v0"): (244.6, 35.4),
    ("ldn", "cartpole-v1"): (231.5, 52.6),
    ("ldn", "cartpole-v2"): (229.5, 18.4),
}
"""Episodes to threshold, (mean, s.d.) over 10 runs."""

PAPER_TABLE3 = {
    ("a2c", "cartpole-v0"): 625.5,
    ("a2c", "cartpole-v1"): 613.2,
    ("a2c", "cartpole-v2"): 723.1,
    ("a2c-model", "cartpole-v0"): 974.4,
    ("a2c-model", "cartpole-v1"): 965.5,
    ("a2c-model", "cartpole-v2"): 1538.1,
    ("ldn", "cartpole-v0"): 931.5,
    ("ldn", "cartpole-v1"): 933.3,
    ("ldn", "cartpole-v2"): 1522.4,
}
"""Wall-clock seconds to threshold."""

PAPER_TABLE4 = {
    "ant": (3124.7, 3882.4),
    "halfcheetah": (5963.3, 6593.2),
    "hopper": (4153.8, 4984.0),
    "reacher": (5546.3, 7624.9),
    "walker2d": (5923.6, 6124.7),
    "inverted_pendulum": (7842.1, 10864.3),
}
"""Total moving reward, (A3C-Model, MBRL-LDN)."""

PAPER_TABLE5 = {
    "inverted_pendulum": (2463, 2465, 2175),
    "halfcheetah": (2601, 2254, 1734),
    "hopper": (2603, 2504, 2397),
}
"""Episodes to reach the top, (PPO2, PPO2-Model, PPO2-LDN)."""

# -- runs ---------------------------------------------------------------------------------------


def run_config(scale: Scale, env: str, algo: str, k: tuple[float, ...] = (1.0,), **model) -> Config:
    """The paper preset at this scale. Raises ValueError for a run this scale does not do:
    the scripts report such rows as pending (MuJoCo tasks outside `scale.mujoco_budgets`,
    which this scale does not budget).

    MuJoCo runs take `scale.mujoco_seeds` and the env's own chunk (`ldn_jax.presets.TASKS`: one
    iteration, up to 8,000 env steps per seed). `model` overrides `ModelConfig` fields."""
    if env in MUJOCO:
        if env not in scale.mujoco_budgets:
            raise ValueError(f"{env} runs at --scale paper only (no budget at this scale)")
        size = {"seeds": scale.mujoco_seeds, **scale.mujoco_budgets[env]}
        if env == "reacher":
            size["max_steps"] = PAPER_STEP_LIMIT  # gymnasium's is 50
    else:
        size = {
            "seeds": scale.seeds,
            "episodes": scale.episodes,
            "chunk_iterations": scale.chunk_iterations,
        }
    config = from_preset(
        "paper", env=env, algo=algo, k=k, workers=scale.workers, model=model, **size
    )
    return validate(config)


FAMILY_ALGOS = ("a2c", "a2c-model", "ldn")
"""The family study's algorithms (`experiments.paper.family`)."""


def family_config(env: str, algo: str, seeds: int) -> Config:
    """A run as `ldn-jax --env ENV --algo ALGO --seeds N --k 1` starts it: the default budget
    and constants, K = 1 (the family study's runs; cpu-full's Table 4 shares them)."""
    return validate(from_preset("paper", env=env, algo=algo, seeds=seeds, k=(1.0,)))


# -- statistics and files -----------------------------------------------------------------------


def describe(values: list[float | None]) -> dict:
    """min, max, mean, s.d. (ddof 1), and the IQM with its bootstrap 95% interval
    (`ldn_jax.host.stats`), over the runs that have a value; `reached` counts them."""
    have = np.array([v for v in values if v is not None], float)
    out = {"reached": int(have.size), "runs": len(values)}
    if have.size == 0:
        return {
            **out,
            "min": None,
            "max": None,
            "mean": None,
            "sd": None,
            "iqm": None,
            "ci95": None,
        }
    sd = float(have.std(ddof=1)) if have.size > 1 else None
    estimate = stats.estimate(have)
    return {
        **out,
        "min": float(have.min()),
        "max": float(have.max()),
        "mean": float(have.mean()),
        "sd": sd,
        "iqm": estimate["iqm"],
        "ci95": estimate["ci95"],
    }


def out_dir(results: Path, name: str) -> Path:
    path = results / name
    path.mkdir(parents=True, exist_ok=True)
    return path


def write_json(path: Path, data: dict, compact: bool = False) -> None:
    """Indented, or with `compact` one line (for files of long arrays); NaN is an error."""
    text = json.dumps(data, indent=None if compact else 1, allow_nan=False)
    path.write_text(text + "\n")


def write_csv(path: Path, rows: list[dict]) -> None:
    """Rows of scalars; a missing or None value is written as an empty cell, an interval
    `ci95` as two columns `ci95_low` and `ci95_high`."""
    rows = [_split_intervals(row) for row in rows]
    fields = list(dict.fromkeys(name for row in rows for name in row))
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _cell(v) for k, v in row.items()})


def _split_intervals(row: dict) -> dict:
    out = {}
    for name, value in row.items():
        if name.endswith("ci95"):
            low, high = value if value is not None else (None, None)
            out |= {f"{name}_low": low, f"{name}_high": high}
        else:
            out[name] = value
    return out


def _cell(value):
    if isinstance(value, float):
        return "" if not math.isfinite(value) else f"{value:.6g}"
    return "" if value is None else value


def scale_record(scale: Scale) -> dict:
    """What every result file records about how it was made."""
    return {
        "scale": scale.name,
        "seeds": scale.seeds,
        "episodes": scale.episodes,
        "workers": scale.workers,
        "preset": "paper",
        "machine": machine(),
    }


def machine() -> dict:
    import jax

    from ldn_jax.host.runtime import host

    found = host()  # the CPU model and versions a run's summary records
    return {
        "cpu": found["cpu"],
        "cores": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "jax_backend": jax.default_backend(),
        "jax": found["jax"],
        "jaxlib": found["jaxlib"],
        "python": platform.python_version(),
        "date": time.strftime("%Y-%m-%d"),
    }
