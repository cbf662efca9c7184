"""Flags -> config: the training command's flags, and the `Config` they describe.

The config's defaults are `Config`'s (`ldn_jax.config`, per-env ones in `from_preset`): a
config flag left out is None here, so that `--resume` can tell which flags were given.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import envs
from experiments.loggers import LOGGERS
from ldn_jax.config import (
    ALGORITHMS,
    IMAGINE_MODES,
    LD_ESTIMATORS,
    PRESETS,
    Config,
    from_preset,
    validate,
)


class UsageError(Exception):
    """Bad input: reported as one line on stderr with exit code 2."""


class Parser(argparse.ArgumentParser):
    """argparse whose errors are one line (a `UsageError`), not usage + message."""

    def error(self, message: str):
        raise UsageError(message)


DESCRIPTION = """\
Train the A2C or PPO family (plain, -model, -ldn) on one env, many seeds and K at once.

    python experiments/run.py --env cartpole-v2 --algo ldn --seeds 5 --k 0.5,1,2

Writes config.json, metrics.jsonl, summary.json, curves.png and checkpoints/ into --out.
`--devices N` splits the seeds over N devices, `--distributed` over several hosts;
`--dry-run` compiles the training program and prints its cost without training.
"""

CONFIG_FLAGS = {
    "env": "env",
    "algo": "algo",
    "seeds": "seeds",
    "k": "k",
    "episodes": "episodes",
    "steps": "steps",
    "workers": "workers",
    "preset": "preset",
    "threshold": "threshold",
    "chunk": "chunk_iterations",
    "backend": "backend",
    "ld": "model.ld",
    "ensemble_size": "model.ensemble",
    "imagine": "model.imagine",
    "support": "model.support",
}
"""CLI flag (its argparse name) -> the config field it sets (`model.X`: a `ModelConfig` field)."""


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    d = Config()
    p = Parser(description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", help=f"one of: {', '.join(envs.names())} (default {d.env})")
    p.add_argument("--algo", help=f"one of: {', '.join(ALGORITHMS)} (default {d.algo})")
    p.add_argument("--seeds", type=int, help=f"number of vmapped seeds 0..N-1 (default {d.seeds})")
    p.add_argument("--k", help=f"comma-separated learning-degree gains K (default {_gains(d.k)})")
    p.add_argument(
        "--episodes",
        type=int,
        help=f"real episodes per seed and K (default {d.episodes} for CartPole; MuJoCo tasks "
        "default to --steps instead: 600000 for inverted_pendulum, 1000000 for the others)",
    )
    p.add_argument(
        "--steps",
        type=int,
        help="instead of --episodes: real env steps per seed and K, summed over workers; each "
        "run stops at the first iteration that reaches them (MuJoCo's natural unit)",
    )
    p.add_argument(
        "--backend",
        help="MuJoCo physics: native (MuJoCo's C engine, fast on CPU), mjx (for GPU/TPU) or "
        "auto (default: native on CPU, mjx on GPU/TPU)",
    )
    p.add_argument("--workers", type=int, help=f"synchronous workers (default {d.workers})")
    p.add_argument("--preset", help=f"one of: {', '.join(PRESETS)} (default {d.preset})")
    p.add_argument("--threshold", type=float, help="moving-return threshold")
    p.add_argument(
        "--chunk", type=int, help=f"iterations per compiled chunk (default {d.chunk_iterations})"
    )
    p.add_argument(
        "--ld",
        choices=LD_ESTIMATORS,
        help="learning-degree estimator: m0 (M1 vs its initial copy M0, the paper) or ensemble "
        "(disagreement of --ensemble-size models relative to their fit error) (default m0)",
    )
    p.add_argument(
        "--ensemble-size",
        type=int,
        metavar="E",
        help=f"members with --ld ensemble (default {d.model.ensemble})",
    )
    p.add_argument(
        "--imagine",
        choices=IMAGINE_MODES,
        help="how imagined steps reach the learner: episodes (learnt from as they are played: "
        "the paper), memory (PPO only: kept in the imaginary memory until a whole rollout's "
        "worth exists) or batch (back-to-back imagined episodes, a fixed n_steps x workers a "
        "iteration) (default: episodes; memory for the PPO family)",
    )
    p.add_argument(
        "--support",
        metavar="FRACTION|none",
        help="stop an imagined episode where M1 predicts an observation outside the box of "
        "real ones, widened by FRACTION of its width each side; none: never (default: 0.1 "
        "for MuJoCo tasks, none for CartPole)",
    )
    p.add_argument("--out", help="run directory (default runs/ENV-ALGO-TIME)")
    p.add_argument("--resume", metavar="DIR", help="continue the run in DIR from its checkpoint")
    p.add_argument(
        "--checkpoint-every", type=int, default=20, help="chunks between checkpoints (0: end only)"
    )
    p.add_argument("--quiet", action="store_true", help="no live progress display")
    p.add_argument("--logger", default="none", choices=LOGGERS, help="extra metric sink")
    p.add_argument(
        "--devices",
        help="devices to split the seeds over: N or 'all' (default 1; with --distributed, all)",
    )
    p.add_argument(
        "--bitwise",
        action="store_true",
        default=None,
        help="metrics identical to the bit (CPU) whatever --devices, for runs that all use "
        "--bitwise: no YNNPACK reduction fusions (about 8%% slower), and a device holding "
        "one seed computes it twice; a resumed run keeps what it was started with",
    )
    p.add_argument(
        "--distributed",
        action="store_true",
        help="multi-host: jax.distributed.initialize (coordinator from the flags below, "
        "JAX_COORDINATOR_ADDRESS, or the cluster: SLURM, Open MPI); process 0 writes the files",
    )
    p.add_argument("--coordinator", metavar="HOST:PORT", help="process 0's address")
    p.add_argument("--num-processes", type=int, help="processes in all (one per host)")
    p.add_argument("--process-id", type=int, help="this process's index, 0..num-processes-1")
    p.add_argument(
        "--compile-cache",
        metavar="DIR",
        help="persistent compilation cache, or 'none' (default $XDG_CACHE_HOME/ldn-jax/jax-cache, "
        "else ~/.cache/ldn-jax/jax-cache)",
    )
    p.add_argument(
        "--dry-run",
        action="store_true",
        help="compile the training chunk, print compile seconds, FLOPs and memory, write nothing",
    )
    args = p.parse_args(argv)
    if args.checkpoint_every < 0:
        raise UsageError("--checkpoint-every must be >= 0")
    cluster = [f for f in ("coordinator", "num_processes", "process_id") if getattr(args, f)]
    if cluster and not args.distributed:
        raise UsageError(f"{flag_name(cluster[0])} needs --distributed")
    if args.distributed and not (args.out or args.resume or args.dry_run):
        raise UsageError("--distributed needs --out (every process must name the same run)")
    return args


def build_config(args: argparse.Namespace) -> Config:
    """The config the flags describe (defaults for those not given), validated; a MuJoCo
    run's `auto` backend resolved. `UsageError` for anything impossible."""
    if args.ensemble_size is not None and args.ld != "ensemble":
        raise UsageError("--ensemble-size needs --ld ensemble")
    if args.steps is not None and args.episodes is not None:
        raise UsageError("give --steps or --episodes, not both (one budget per run)")
    overrides: dict = {}
    for flag, field in CONFIG_FLAGS.items():
        value = getattr(args, flag)
        if value is None or flag == "preset":
            continue
        if flag == "k":
            value = parse_k(value)
        if flag == "support":
            value = parse_support(value)
        if field.startswith("model."):
            overrides.setdefault("model", {})[field.split(".", 1)[1]] = value
        else:
            overrides[field] = value
    try:
        config = validate(from_preset(args.preset or Config.preset, **overrides))
    except ValueError as error:
        raise UsageError(str(error)) from None
    return resolve_physics(config)


def resolve_physics(config: Config) -> Config:
    """A MuJoCo run records the engine `auto` picked, and its model must load (one line
    otherwise); other envs keep the config as it is."""
    if config.env not in envs.mujoco.TASKS:
        return config
    backend = envs.mujoco.resolve_backend(config.backend)
    try:
        envs.mujoco.engine(config.env, backend)
    except envs.mujoco.ModelError as error:
        raise UsageError(f"--backend {backend}: {error}") from None
    return dataclasses.replace(config, backend=backend)


def check_resume_flags(args: argparse.Namespace, config: Config) -> None:
    """Flags given with `--resume` must agree with the stored config."""
    for flag, field in CONFIG_FLAGS.items():
        value = getattr(args, flag)
        if value is None:
            continue
        stored = config
        for part in field.split("."):
            stored = getattr(stored, part)
        if flag == "backend" and value == "auto" and config.env in envs.mujoco.TASKS:
            value = envs.mujoco.resolve_backend(value)
        if flag == "support":
            value = parse_support(value)
        if flag == "k":
            value = parse_k(value)
            stored = tuple(stored)
            if not config.uses_k:
                value = value[:1]
        if value != stored:
            raise UsageError(
                f"{flag_name(flag)} {getattr(args, flag)} does not match the run being resumed "
                f"({field} = {stored}); drop the flag to resume"
            )
    if args.out is not None and Path(args.out).resolve() != Path(args.resume).resolve():
        raise UsageError("--out and --resume name different directories; give --resume alone")


def parse_k(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise UsageError(f"--k must be comma-separated numbers, got {text!r}") from None


def parse_support(text: str) -> float | None:
    if text.strip().lower() == "none":
        return None
    try:
        return float(text)
    except ValueError:
        raise UsageError(f"--support must be a number or none, got {text!r}") from None


def flag_name(name: str) -> str:
    """argparse's name of a flag -> how the user types it (`ensemble_size` -> --ensemble-size)."""
    return "--" + name.replace("_", "-")


def _gains(k: tuple[float, ...]) -> str:
    return ",".join(f"{v:g}" for v in k)
