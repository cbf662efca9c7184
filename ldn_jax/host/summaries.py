"""What a run reports: metrics lines, the live status, warnings, summary.json, curves.png and
the closing line. Numpy in, plain data out; the run directory writes it."""

from __future__ import annotations

import json
import sys

import numpy as np

from ldn_jax import sharding
from ldn_jax.config import Config
from ldn_jax.host import stats
from ldn_jax.host.metrics import completed_returns, run_crossing
from ldn_jax.host.plots import learning_curves
from ldn_jax.host.run_dir import RunDir
from ldn_jax.trainer import failure_names

LOSS_SUFFIXES = (
    "_loss",
    "_entropy",
    "_approx_kl",
    "_clip_fraction",
    "_kl_stopped",
    "_alpha",
    "_epochs",
)
"""Metrics written under "losses" in metrics.jsonl."""


def run_name(config: Config, point: int, seed: int) -> str:
    """How messages name one run of the batch: `seed 1 K=0.5`, or `seed 1` where K is unused,
    with a sweep's values (`seed 1 agent.actor_lr=0.0003`)."""
    return " ".join(filter(None, [f"seed {config.first_seed + seed}", config.point_name(point)]))


def point_fields(config: Config, point: int) -> dict:
    """What metrics.jsonl and summary.json say of a point: its K, and in a sweep its values
    (`"sweep": {field: value}`)."""
    values = dict(config.points[point])
    k = values.pop("k")
    return {"k": k, "sweep": values} if config.sweep else {"k": k}


def metric_lines(
    config: Config, metrics: dict, wall_seconds: float, first_iteration: int
) -> list[str]:
    """One JSON line per K, seed and iteration of a chunk's metrics `[K, S, N, ...]`.

    `iteration` counts the host's iterations from `first_iteration`, so a run frozen by the
    non-finite guard still numbers its lines like the others.
    """
    lines = []
    losses = [name for name in metrics if name.endswith(LOSS_SUFFIXES)]
    n_k, seeds, n_iter = metrics["iteration"].shape
    for ki in range(n_k):
        for seed in range(seeds):
            for i in range(n_iter):
                at = lambda name, index=(ki, seed, i): metrics[name][index]
                line = {
                    "iteration": first_iteration + i,
                    "seed": config.first_seed + seed,
                    **point_fields(config, ki),
                    "episodes": int(at("episodes")),
                    "env_steps": int(at("env_steps")),
                    "imagined_steps": int(at("imagined_steps")),
                    "episode_return": finite_or_none(at("episode_return")),
                    "moving_return": float(at("moving_return")),
                    "ld_mean": finite_or_none(at("ld_mean")) if "ld_mean" in metrics else None,
                    "losses": {name: finite_or_none(at(name)) for name in losses},
                    "wall_seconds": round(wall_seconds, 3),
                }
                if "greedy_return" in metrics:  # `solved_return`: the chunk's evaluation
                    line["greedy_return"] = finite_or_none(at("greedy_return"))
                lines.append(json.dumps(line))
    return lines


def finite_or_none(value) -> float | None:
    value = float(value)
    return value if np.isfinite(value) else None


def _mean(values: np.ndarray) -> float:
    """The mean of the finite values; NaN where there is none (no episode has ended yet),
    without numpy's warning."""
    finite = np.asarray(values)[np.isfinite(values)]
    return float(finite.mean()) if finite.size else float("nan")


def status(metrics: dict, train_seconds: float) -> str:
    """The live display's text after a chunk."""
    steps = int(metrics["env_steps"].sum(axis=(0, 1))[-1])
    text = f"moving return {_mean(metrics['moving_return'][..., -1]):7.1f}"
    if "ld_mean" in metrics:
        text += f"  LD {_mean(metrics['ld_mean'][..., -1]):.3f}"
    return text + f"  {steps / max(train_seconds, 1e-9):,.0f} env steps/s"


def report_failures(config: Config, failure: np.ndarray | None, reported: set) -> set:
    """One stderr line per run of `failure [K, S]` that newly became non-finite; returns all
    reported so far."""
    if failure is None:
        return reported
    for ki, seed in zip(*np.nonzero(failure), strict=True):
        if (ki, seed) not in reported:
            what = ", ".join(failure_names(int(failure[ki, seed])))
            print(
                f"warning: {run_name(config, ki, seed)}: non-finite {what}; this run is "
                "frozen at its last finite state, the others go on",
                file=sys.stderr,
            )
            reported = reported | {(ki, seed)}
    return reported


def summarize(config: Config, history: dict, eval_returns, states, session: dict) -> dict:
    """summary.json's contents from the whole history `{name: [K, S, N, ...]}`."""
    threshold = config.resolved_threshold
    chunk_ends = session["chunk_ends"]
    train_seconds = chunk_ends[-1]
    failure, failed_iteration = sharding.to_host((states.failure, states.failed_iteration))
    total_steps = int(history["env_steps"][..., -1].sum())
    runs = []
    per_chunk = config.chunk_iterations
    for ki in range(len(config.points)):
        for seed in range(config.seeds):
            crossing = None
            if threshold is not None:
                crossing = run_crossing(history, (ki, seed), threshold)
            seconds = None
            if crossing is not None:
                # Wall time of the whole vmapped batch, pro rata within the crossing's chunk.
                chunk, within = divmod(crossing[2], per_chunk)
                begin = chunk_ends[chunk - 1] if chunk else 0.0
                seconds = begin + (chunk_ends[chunk] - begin) * (within + 1) / per_chunk
            runs.append(
                {
                    "seed": config.first_seed + seed,
                    **point_fields(config, ki),
                    "episodes_to_threshold": crossing[0] if crossing else None,
                    "env_steps_to_threshold": crossing[1] if crossing else None,
                    "seconds_to_threshold": round(seconds, 3) if seconds else None,
                    "final_moving_return": finite_or_none(history["moving_return"][ki, seed, -1]),
                    "eval_return": float(eval_returns[ki, seed]),
                    "solved": solved_at(config, history, (ki, seed), chunk_ends),
                    "diverged": None
                    if failure[ki, seed] == 0
                    else {
                        "iteration": int(failed_iteration[ki, seed]),
                        "quantities": failure_names(int(failure[ki, seed])),
                    },
                }
            )
    return {
        "env": config.env,
        "algo": config.algo,
        "backend": config.backend,
        "statistics": statistics(config, runs),
        "budget": {"steps": config.steps} if config.steps else {"episodes": config.episodes},
        "real_episodes": int(history["episodes"][..., -1].sum()),
        "env_steps": total_steps,
        "threshold": threshold,
        "solved_return": config.solved_return,
        "compile_seconds": round(session["compile_seconds"], 3),
        "train_seconds": round(train_seconds, 3),
        "env_steps_per_second": round(total_steps / train_seconds, 1),
        "imagined_steps": int(history["imagined_steps"][..., -1].sum()),
        "resumes": session["resumes"],
        "runs": runs,
    }


def solved_at(config: Config, history: dict, run: tuple[int, int], chunk_ends) -> dict | None:
    """Where one run's greedy evaluation first reached `config.solved_return`, the run
    stopping there: `{"episodes", "env_steps", "seconds"}` (seconds: the batch's wall time
    at the end of that chunk); None if it never did (or no `solved_return`)."""
    if config.solved_return is None:
        return None
    reached = np.flatnonzero(history["greedy_return"][run] >= config.solved_return)
    if not len(reached):
        return None
    at = reached[0]
    return {
        "episodes": int(history["episodes"][run][at]),
        "env_steps": int(history["env_steps"][run][at]),
        "seconds": round(chunk_ends[at // config.chunk_iterations], 3),
    }


STATISTICS = (
    "episodes_to_threshold",
    "env_steps_to_threshold",
    "final_moving_return",
    "eval_return",
)
"""The per-run results `statistics` summarises over seeds."""


def statistics(config: Config, runs: list[dict]) -> list[dict]:
    """Per point (K, and a sweep's values), each of `STATISTICS` over the seeds: the
    interquartile mean with its bootstrap 95% interval, beside mean and s.d.
    (`ldn_jax.host.stats.estimate`). To-threshold counts are over the runs that reached it
    (`reached` of `runs`)."""
    out = []
    for index in range(len(config.points)):
        point = point_fields(config, index)
        here = [r for r in runs if all(r[n] == v for n, v in point.items())]
        entry = {**point, "runs": len(here)}
        entry["reached"] = sum(r["episodes_to_threshold"] is not None for r in here)
        if config.solved_return is not None:
            entry["solved"] = sum(r["solved"] is not None for r in here)
        for name in STATISTICS:
            values = [r[name] for r in here if r[name] is not None]
            entry[name] = stats.estimate(values)
        out.append(entry)
    return out


def plot_curves(config: Config, history: dict, run: RunDir) -> None:
    """curves.png: the moving return after every real episode, in completion order (mean and
    band over seeds), one line per K; a run of a few iterations still draws a curve."""
    label = lambda i: " ".join([config.algo, config.point_name(i)]).strip()
    curves = {}
    for i in range(len(config.points)):
        runs = [completed_returns(history, (i, seed)) for seed in range(config.seeds)]
        shortest = min(len(r) for r in runs)  # schedule "steps": seeds end unequal counts
        returns = np.stack([r[:shortest] for r in runs])
        curves[label(i) if len(config.points) > 1 else config.algo] = (
            np.arange(1, shortest + 1),
            returns,
        )
    title = f"{config.env}: {config.algo}"
    learning_curves(curves, run.curves_file, title, config.resolved_threshold)


def closing_lines(config: Config, summary: dict, run: RunDir) -> None:
    """What a finished run prints: runs that reached the threshold, times, where the files are."""
    runs = summary["runs"]
    if summary["threshold"] is not None:
        reached = [r for r in runs if r["episodes_to_threshold"] is not None]
        outcome = f"{len(reached)}/{len(runs)} runs reached {summary['threshold']}"
        if len(reached) > 1:
            many = len(summary["statistics"]) > 1
            iqms = [
                stats.text(s["episodes_to_threshold"])
                + (f" ({config.point_name(i)})" if many and config.point_name(i) else "")
                for i, s in enumerate(summary["statistics"])
            ]
            outcome += f", episodes to it: IQM [95% CI] {'; '.join(iqms)}"
    else:  # no threshold to reach: what the runs ended at
        final = [r["final_moving_return"] for r in runs if r["final_moving_return"] is not None]
        final_text = stats.text(stats.estimate(final), 1) if final else "none finite"
        evals = stats.text(stats.estimate([r["eval_return"] for r in runs]), 1)
        outcome = (
            f"final moving return {final_text}, greedy eval return {evals} "
            f"(IQM [95% CI] over {len(runs)} runs)"
        )
    if config.solved_return is not None:
        solved = [r["solved"] for r in runs if r["solved"] is not None]
        outcome += f"; {len(solved)}/{len(runs)} solved (greedy {config.solved_return:g})"
        if solved:
            outcome += f", the last after {max(s['seconds'] for s in solved):.1f}s"
    print(
        f"{config.env} {config.algo}: {outcome}; compile {summary['compile_seconds']:.1f}s, "
        f"train {summary['train_seconds']:.1f}s, eval {summary['eval_seconds']:.1f}s "
        f"({summary['eval_share']:.0%} of training), "
        f"{summary['env_steps_per_second']:,.0f} env steps/s"
    )
    diverged = [r for r in summary["runs"] if r["diverged"]]
    if diverged:
        print(f"{len(diverged)} run(s) diverged and were frozen: see summary.json", file=sys.stderr)
    print(f"curves:  {run.curves_file}\nsummary: {run.summary_file}")
