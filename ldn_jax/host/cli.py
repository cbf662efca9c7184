"""The `ldn-jax` command: train (the default), evaluate in gymnasium, compare runs.

    ldn-jax --env cartpole-v2 --algo ldn --seeds 5 --k 0.5,1,2   (train: experiments/run.py)
    ldn-jax eval RUN_DIR [--seed S] [--k K] [--episodes N] [--video DIR]
    ldn-jax plot RUN_DIR [RUN_DIR ...] [--out PNG]
    ldn-jax compare RUN_DIR [RUN_DIR ...] [--json FILE]

Bad input gets a one-line error on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import gymnasium
import numpy as np

from ldn_jax import load_policy
from ldn_jax.host import compare as comparison
from ldn_jax.host import flags, gym_eval, run
from ldn_jax.host.flags import Parser
from ldn_jax.host.plots import compare_runs
from ldn_jax.host.policy import point_index
from ldn_jax.host.run_dir import RunDir, RunDirError
from ldn_jax.host.settings import UsageError


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `ldn-jax` console script; returns the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    commands = {"train": run.main, "eval": evaluate, "plot": plot, "compare": compare}
    if argv and argv[0] in commands:
        return commands[argv[0]](argv[1:])
    if argv and argv[0] in ("-h", "--help"):
        print(__doc__)
    return run.main(argv)


def evaluate(argv: list[str]) -> int:
    """`ldn-jax eval`: a trained greedy policy in the gymnasium env; writes RUN_DIR/eval.json."""
    p = eval_parser()
    try:
        args = p.parse_args(argv)
        config, act, k, point = _load(args)
        render = "rgb_array" if args.video else None
        env = gym_eval.make_env(config.env, render, max_steps=config.episode_limit)
        name = f"seed{args.seed}_k{k:g}" + "".join(f"_{n}={v:g}" for n, v in point.items())
        returns = _episode_returns(env, act, args, name)
    except (UsageError, ValueError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    mean = float(returns.mean())
    std = float(returns.std(ddof=1)) if len(returns) > 1 else 0.0
    result = {
        "seed": args.seed,
        "k": k,
        **({"sweep": point} if config.sweep else {}),
        "episodes": args.episodes,
        "env_seed": args.env_seed,
        "mean_return": mean,
        "std_return": std,
        "returns": returns.tolist(),
    }
    run_dir = RunDir(args.run_dir)
    header = {"env": config.env, "gymnasium": gym_eval.gymnasium_name(config.env)}
    run_dir.record_eval(header, result)
    which = f"seed {args.seed}" + (f" K={k:g}" if config.uses_k else "")
    which += "".join(f" {name}={value:g}" for name, value in point.items())
    print(
        f"{config.env} {config.algo} {which} in gymnasium "
        f"{gym_eval.gymnasium_name(config.env)}: return {mean:.1f} ± {std:.1f} (s.d.) "
        f"over {args.episodes} episodes -> {run_dir.eval_file}"
    )
    return 0


def _load(args: argparse.Namespace):
    """`(config, act, k, sweep values)` of the run, or UsageError."""
    run_dir = args.run_dir
    if not run_dir.is_dir():
        raise UsageError(f"no such run directory: {run_dir}")
    if args.episodes < 1:
        raise UsageError(f"--episodes must be >= 1, got {args.episodes}")
    run = RunDir(run_dir)
    try:
        config = run.read_config()
    except RunDirError as error:
        raise UsageError(str(error)) from None
    if not run.has_final_checkpoint():
        raise UsageError(f"{run_dir} has no final checkpoint (training not finished?)")
    at = {}
    for item in args.at:
        name, sep, value = item.partition("=")
        try:
            at[name.strip()] = float(value)
        except ValueError:
            raise UsageError(f"--at needs FIELD=NUMBER, got {item!r}") from None
        if not sep:
            raise UsageError(f"--at needs FIELD=NUMBER, got {item!r}")
    # ValueError names the valid seeds, K and sweep values
    if args.seed is None:
        args.seed = config.first_seed
    act = load_policy(run_dir, args.seed, args.k, at)
    values = dict(config.points[point_index(config, args.k, at)])
    return config, act, values.pop("k"), values


def _episode_returns(env: gymnasium.Env, act, args: argparse.Namespace, name: str) -> np.ndarray:
    """The returns of `args.episodes` episodes; with `--video`, recorded under `name`."""
    try:
        if args.video:
            env = gym_eval.record_video(env, args.video, name)
        try:
            return gym_eval.episode_returns(env, act, args.episodes, args.env_seed)
        finally:
            env.close()  # RecordVideo writes its last video here
    except (gymnasium.error.Error, ImportError, OSError, RuntimeError) as error:
        if not args.video:
            raise
        # Rendering and encoding fail in many ways (no moviepy, no pygame, no ffmpeg).
        message = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise UsageError(f"--video failed: {message}") from None


def plot(argv: list[str]) -> int:
    """`ldn-jax plot`: overlay runs' moving return vs episodes (mean, 95% band over seeds)."""
    p = plot_parser()
    try:
        args = p.parse_args(argv)
        compare_runs(args.run_dirs, args.out)
    except (UsageError, ValueError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except OSError as error:
        print(f"error: cannot write {args.out}: {error.strerror or error}", file=sys.stderr)
        return 2
    print(f"comparison: {args.out}")
    return 0


def compare(argv: list[str]) -> int:
    """`ldn-jax compare`: runs side by side: IQM over seeds with bootstrap 95% intervals of
    episodes and env steps to threshold, final moving return and greedy eval return, and
    each run's probability of improvement over the first run on its env."""
    p = compare_parser()
    try:
        args = p.parse_args(argv)
        table = comparison.rows(args.run_dirs)
        better = comparison.improvements(table)
        if args.json is not None:
            args.json.write_text(json.dumps({"runs": table, "improvement": better}, indent=1))
    except (UsageError, ValueError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except OSError as error:
        print(f"error: cannot write {args.json}: {error.strerror or error}", file=sys.stderr)
        return 2
    print("\n".join(comparison.render(table, better)))
    return 0


def eval_parser() -> Parser:
    p = Parser(prog="ldn-jax eval", description=evaluate.__doc__)
    p.add_argument("run_dir", type=Path, help="a finished run directory")
    p.add_argument(
        "--seed", type=int, default=None, help="which trained seed (default: the run's first, 0)"
    )
    p.add_argument("--k", type=float, default=None, help="which K (default: the run's first)")
    p.add_argument(
        "--at",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="in a sweep, which point (repeatable; a field left out: its first value)",
    )
    p.add_argument("--episodes", type=int, default=100, help="evaluation episodes")
    p.add_argument("--env-seed", type=int, default=0, help="seed of the first env reset")
    p.add_argument("--video", type=Path, default=None, help="save videos (rgb_array) here")
    return p


def plot_parser() -> Parser:
    p = Parser(prog="ldn-jax plot", description=plot.__doc__)
    p.add_argument("run_dirs", type=Path, nargs="+", metavar="RUN_DIR", help="run directories")
    p.add_argument("--out", type=Path, default=Path("comparison.png"), help="the PNG to write")
    return p


def compare_parser() -> Parser:
    p = Parser(prog="ldn-jax compare", description=compare.__doc__)
    p.add_argument("run_dirs", type=Path, nargs="+", metavar="RUN_DIR", help="run directories")
    p.add_argument("--json", type=Path, default=None, help="also write the tables here")
    return p


def parsers() -> dict[str, Parser]:
    """Every subcommand's parser, by the command a user types (the docs' flag tables)."""
    train = flags.parser()
    train.prog = "ldn-jax train"
    return {
        "ldn-jax train": train,
        "ldn-jax eval": eval_parser(),
        "ldn-jax plot": plot_parser(),
        "ldn-jax compare": compare_parser(),
    }


if __name__ == "__main__":
    sys.exit(main())
