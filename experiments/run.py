"""Train the A2C or PPO family (plain, -model, -ldn) on one env, many seeds and K at once.

    python experiments/run.py --env cartpole-v2 --algo ldn --seeds 5 --k 0.5,1,2

Writes config.json, metrics.jsonl, summary.json, curves.png and checkpoints/ into --out.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import envs
from experiments.loggers import LOGGERS, Logger, NullLogger, make_logger
from experiments.plots import learning_curves
from ldn_jax import checkpoint
from ldn_jax.config import ALGORITHMS, PRESETS, Config, from_preset, validate
from ldn_jax.metrics import threshold_crossing
from ldn_jax.policy import FINAL_CHECKPOINT
from ldn_jax.train import Trainer


class UsageError(Exception):
    """Bad input: reported as one line on stderr with exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, not usage + message
        raise UsageError(message)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = _Parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", default="cartpole-v2", help=f"one of: {', '.join(envs.names())}")
    p.add_argument("--algo", default="ldn", help=f"one of: {', '.join(ALGORITHMS)}")
    p.add_argument("--seeds", type=int, default=5, help="number of vmapped seeds (0..N-1)")
    p.add_argument("--k", default="0.5,1,2", help="comma-separated learning-degree gains K")
    p.add_argument("--episodes", type=int, default=1600, help="real episodes per seed and K")
    p.add_argument("--workers", type=int, default=None, help="synchronous workers (default 8)")
    p.add_argument("--preset", default="paper", help=f"one of: {', '.join(PRESETS)}")
    p.add_argument("--threshold", type=float, default=None, help="moving-return threshold")
    p.add_argument("--out", default=None, help="run directory (default runs/ENV-ALGO-TIME)")
    p.add_argument(
        "--chunk", type=int, default=None, help="iterations per compiled chunk (default 5)"
    )
    p.add_argument(
        "--checkpoint-every", type=int, default=20, help="chunks between checkpoints (0: end only)"
    )
    p.add_argument("--quiet", action="store_true", help="no live progress display")
    p.add_argument("--logger", default="none", choices=LOGGERS, help="extra metric sink")
    return p.parse_args(argv)


def build_config(args: argparse.Namespace) -> Config:
    try:
        k = tuple(float(v) for v in args.k.split(",") if v.strip())
    except ValueError:
        raise UsageError(f"--k must be comma-separated numbers, got {args.k!r}") from None
    overrides = {"env": args.env, "algo": args.algo, "seeds": args.seeds, "episodes": args.episodes}
    overrides["k"] = k if ALGORITHMS.get(args.algo, ALGORITHMS["ldn"]).ld_stop else k[:1] or k
    for name, value in (("workers", args.workers), ("chunk_iterations", args.chunk)):
        if value is not None:
            overrides[name] = value
    if args.threshold is not None:
        overrides["threshold"] = args.threshold
    if args.checkpoint_every < 0:
        raise UsageError("--checkpoint-every must be >= 0")
    try:
        return validate(from_preset(args.preset, **overrides))
    except ValueError as error:
        raise UsageError(str(error)) from None


def prepare_out(args: argparse.Namespace, config: Config) -> Path:
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = Path(args.out) if args.out else Path("runs") / f"{config.env}-{config.algo}-{stamp}"
    if (out / "config.json").exists():
        raise UsageError(f"{out} already holds a run; choose another --out")
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as error:
        raise UsageError(f"cannot write to --out {out}: {error.strerror or error}") from None
    return out


def write_json(path: Path, data: dict) -> None:
    """Write atomically: a reader sees the old file or the new one, never half of one."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    os.replace(tmp, path)


LOSS_SUFFIXES = ("_loss", "_entropy", "_approx_kl", "_clip_fraction")
"""Metrics written under "losses" in metrics.jsonl."""


def metric_lines(config: Config, metrics: dict, wall_seconds: float) -> list[str]:
    """One JSON line per K, seed and iteration of a chunk's metrics `[K, S, N, ...]`."""
    lines = []
    losses = [name for name in metrics if name.endswith(LOSS_SUFFIXES)]
    n_k, seeds, n_iter = metrics["iteration"].shape
    for ki in range(n_k):
        for seed in range(seeds):
            for i in range(n_iter):
                at = lambda name, index=(ki, seed, i): metrics[name][index]
                line = {
                    "iteration": int(at("iteration")),
                    "seed": seed,
                    "k": config.k[ki],
                    "episodes": int(at("episodes")),
                    "env_steps": int(at("env_steps")),
                    "imagined_steps": int(at("imagined_steps")),
                    "episode_return": float(at("episode_return")),
                    "moving_return": float(at("moving_return")),
                    "ld_mean": _finite_or_none(at("ld_mean")) if "ld_mean" in metrics else None,
                    "losses": {name: _finite_or_none(at(name)) for name in losses},
                    "wall_seconds": round(wall_seconds, 3),
                }
                lines.append(json.dumps(line))
    return lines


def _finite_or_none(value) -> float | None:
    value = float(value)
    return value if np.isfinite(value) else None


class Progress:
    """Live display of episodes, moving return, LD and throughput (rich), or nothing."""

    def __init__(self, total: int, quiet: bool):
        self.quiet = quiet
        if quiet:
            return
        from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn
        from rich.progress import Progress as RichProgress

        self.bar = RichProgress(
            TextColumn("[bold]episodes"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TextColumn("{task.fields[status]}"),
        )
        self.task = self.bar.add_task("train", total=total, status="compiling...")
        self.bar.start()

    def update(self, episodes: int, status: str) -> None:
        if not self.quiet:
            self.bar.update(self.task, completed=episodes, status=status)

    def stop(self) -> None:
        if not self.quiet:
            self.bar.stop()


def train(
    config: Config, out: Path, checkpoint_every: int, quiet: bool, logger: Logger | None = None
) -> dict:
    logger = logger or NullLogger()
    trainer = Trainer(config)
    write_json(out / "config.json", config.to_dict())
    states = trainer.init_batch()
    k = trainer.k_values()
    chunks = config.iterations // config.chunk_iterations
    progress = Progress(config.iterations * config.workers, quiet)

    start = time.perf_counter()
    chunk_fn = trainer.batched_chunk().lower(states, k).compile()
    compile_seconds = time.perf_counter() - start

    history: dict[str, list[np.ndarray]] = {}
    train_seconds = 0.0
    chunk_ends = []
    with open(out / "metrics.jsonl", "a") as log:
        for chunk in range(chunks):
            t0 = time.perf_counter()
            states, metrics = chunk_fn(states, k)
            metrics = jax.device_get(metrics)
            train_seconds += time.perf_counter() - t0
            chunk_ends.append(train_seconds)
            for name, value in metrics.items():
                history.setdefault(name, []).append(value)
            log.write("\n".join(metric_lines(config, metrics, train_seconds)) + "\n")
            log.flush()
            logger.log(config, metrics, train_seconds)
            episodes = int(metrics["episodes"][0, 0, -1])
            steps = int(metrics["env_steps"].sum(axis=(0, 1))[-1])
            status = f"moving return {metrics['moving_return'][..., -1].mean():7.1f}"
            if "ld_mean" in metrics:
                status += f"  LD {np.nanmean(metrics['ld_mean'][..., -1]):.3f}"
            status += f"  {steps / train_seconds:,.0f} env steps/s"
            progress.update(episodes, status)
            if checkpoint_every and (chunk + 1) % checkpoint_every == 0 and chunk + 1 < chunks:
                checkpoint.save(out / "checkpoints" / f"chunk_{chunk + 1:05d}", states)
    progress.stop()
    logger.close()

    checkpoint.save(out / "checkpoints" / FINAL_CHECKPOINT, states)
    eval_returns = jax.device_get(
        trainer.batched_evaluate()(states, jax.random.key(config.seeds + 10_000))
    )
    history = {name: np.concatenate(parts, axis=2) for name, parts in history.items()}
    summary = summarize(config, history, eval_returns, chunk_ends, compile_seconds, train_seconds)
    write_json(out / "summary.json", summary)
    plot(config, history, out / "curves.png")
    return summary


def summarize(config, history, eval_returns, chunk_ends, compile_seconds, train_seconds) -> dict:
    threshold = config.resolved_threshold
    total_steps = int(history["env_steps"][..., -1].sum())
    runs = []
    per_chunk = config.chunk_iterations
    for ki, k in enumerate(config.k):
        for seed in range(config.seeds):
            crossing = None
            if threshold is not None:
                crossing = threshold_crossing(
                    history["moving_after"][ki, seed],
                    history["lengths"][ki, seed],
                    history["env_steps"][ki, seed],
                    threshold,
                )
            seconds = None
            if crossing is not None:
                # Wall time of the whole vmapped batch, pro rata within the crossing's chunk.
                chunk, within = divmod(crossing[2], per_chunk)
                begin = chunk_ends[chunk - 1] if chunk else 0.0
                seconds = begin + (chunk_ends[chunk] - begin) * (within + 1) / per_chunk
            runs.append(
                {
                    "seed": seed,
                    "k": k,
                    "episodes_to_threshold": crossing[0] if crossing else None,
                    "env_steps_to_threshold": crossing[1] if crossing else None,
                    "seconds_to_threshold": round(seconds, 3) if seconds else None,
                    "final_moving_return": float(history["moving_return"][ki, seed, -1]),
                    "eval_return": float(eval_returns[ki, seed]),
                }
            )
    return {
        "env": config.env,
        "algo": config.algo,
        "threshold": threshold,
        "compile_seconds": round(compile_seconds, 3),
        "train_seconds": round(train_seconds, 3),
        "env_steps_per_second": round(total_steps / train_seconds, 1),
        "imagined_steps": int(history["imagined_steps"][..., -1].sum()),
        "runs": runs,
    }


def plot(config: Config, history: dict, path: Path) -> None:
    episodes = history["episodes"][0, 0]
    curves = {
        (f"{config.algo} K={k:g}" if len(config.k) > 1 else config.algo): (
            episodes,
            history["moving_return"][ki],
        )
        for ki, k in enumerate(config.k)
    }
    learning_curves(curves, path, f"{config.env}: {config.algo}", config.resolved_threshold)


def main(argv: list[str] | None = None) -> int:
    try:
        args = parse_args(argv)
        config = build_config(args)
        out = prepare_out(args, config)
        logger = make_logger(args.logger, out)
    except (UsageError, ValueError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    summary = train(config, out, args.checkpoint_every, args.quiet, logger)
    reached = [r for r in summary["runs"] if r["episodes_to_threshold"] is not None]
    print(
        f"{config.env} {config.algo}: {len(reached)}/{len(summary['runs'])} runs reached "
        f"{summary['threshold']}; compile {summary['compile_seconds']:.1f}s, "
        f"train {summary['train_seconds']:.1f}s, "
        f"{summary['env_steps_per_second']:,.0f} env steps/s"
    )
    print(f"curves:  {out / 'curves.png'}\nsummary: {out / 'summary.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
