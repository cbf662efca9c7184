"""The host loop: run compiled chunks, write metrics and checkpoints between them, stop
cleanly on a signal, evaluate and summarise at the end.

    summary = train(config, out, TrainOptions(checkpoint_every=10, quiet=True))
    summary = train(config, out, checkpoint_every=10, quiet=True)   # the same
"""

from __future__ import annotations

import dataclasses
import signal
import sys
import time
from pathlib import Path

import jax
import numpy as np

from ldn_jax import sharding
from ldn_jax.config import Config
from ldn_jax.host import summaries
from ldn_jax.host.loggers import Logger, NullLogger
from ldn_jax.host.run_dir import FINAL, RunDir
from ldn_jax.host.runtime import compile_chunk, evaluator, host
from ldn_jax.trainer import Trainer


class Interrupted(Exception):
    """Training stopped on request after a checkpoint; `--resume` continues it."""

    def __init__(self, signum: int, chunks_done: int, chunks: int | None):
        """`chunks`: the run's chunks in all; None under a `steps` budget (not known)."""
        self.progress = f"{chunks_done}/{chunks}" if chunks else f"{chunks_done}"
        super().__init__(f"stopped after chunk {self.progress}")
        self.signum, self.chunks_done, self.chunks = signum, chunks_done, chunks


class Stop:
    """SIGINT/SIGTERM set a flag; the loop finishes its chunk, checkpoints and stops.

    A second signal acts at once (the default handler), for a user who cannot wait.
    """

    def __init__(self):
        self.signum: int | None = None

    def install(self) -> Stop:
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, self._handle)
        return self

    def _handle(self, signum, frame) -> None:
        self.signum = signum
        signal.signal(signum, signal.SIG_DFL)

    def requested(self, chunks_done: int) -> bool:
        return self.signum is not None


@dataclasses.dataclass
class TrainOptions:
    """How to train a config, as opposed to what: none of this changes a number."""

    checkpoint_every: int = 20
    """Chunks between checkpoints (0: only the final one)."""
    quiet: bool = False
    """No live progress display."""
    stop: Stop | None = None
    """Asked between chunks whether to checkpoint and raise `Interrupted` (None: never)."""
    resume: bool = False
    """Continue from the newest whole checkpoint in the run directory."""
    logger: Logger | None = None
    """An extra metric sink (TensorBoard ...) beside metrics.jsonl."""
    mesh: object = None
    """`ldn_jax.sharding.seed_mesh` to split the seeds over its devices; None: one device."""
    bitwise: bool | None = None
    """A device with a single seed computes it twice (`ldn_jax.sharding.shard_seeds`);
    None: as the run being resumed was (else False)."""


def train(config: Config, out: Path, options: TrainOptions | None = None, **fields) -> dict:
    """Train (or, with `options.resume`, continue) the run in `out`; returns the summary.

    `fields` set `TrainOptions` fields directly. Across hosts only process 0 writes files.
    Raises `Interrupted` after checkpointing when `options.stop` asks for it between chunks,
    `ldn_jax.host.run_dir.RunDirError` (one line) for a run directory it cannot use or write.
    """
    if options is not None and not isinstance(options, TrainOptions):
        raise TypeError(f"options must be TrainOptions, got {options!r} (or pass fields by name)")
    options = dataclasses.replace(options or TrainOptions(), **fields)
    run, mesh = RunDir(out), options.mesh
    writer = jax.process_index() == 0
    trainer = Trainer(config)
    chunks = config.iterations // config.chunk_iterations
    history: dict[str, list[np.ndarray]] = {}
    session = {"chunks_done": 0, "chunk_ends": [], "compile_seconds": None, "resumes": 0}
    if options.resume and writer:
        run.remove_partial_checkpoints()
    found, skipped = (None, [])
    if options.resume:
        found, skipped = run.load_latest(jax.eval_shape(trainer.init_batch))
    for reason in skipped:
        print(f"warning: {reason}; resuming from {found.name} instead", file=sys.stderr)
    if found is not None:
        states, session = found.states, found.session
        history = {name: [values] for name, values in found.history.items()}
        session["resumes"] += 1
    else:
        if writer:
            run.path.mkdir(parents=True, exist_ok=True)
            run.write_config(config)
        states = trainer.init_batch()
    bitwise = session.get("bitwise", False) if options.bitwise is None else options.bitwise
    session["bitwise"] = bitwise
    if writer:
        run.truncate_metrics(session["chunks_done"] * config.chunk_iterations)
    last_failure = history["failure"][-1][..., -1] if history.get("failure") else None
    reported = summaries.report_failures(config, last_failure, set())
    k = trainer.point_values()
    if mesh is not None:
        states, k = sharding.place(states, mesh), sharding.replicate(k, mesh)

    done = lambda: session["chunks_done"] >= chunks or budget_spent(config, history)
    progress = Progress(config, options.quiet or not writer)
    progress.update(history, "compiling..." if not done() else "evaluating...")
    try:
        if not done():
            chunk_fn, lower_s, compile_s = compile_chunk(
                trainer, states, k, mesh, bitwise, reuse=True
            )
            if session["compile_seconds"] is None:
                session["compile_seconds"] = lower_s + compile_s
            loop = ChunkLoop(config, options, run, history, session, progress, reported)
            states = _train_chunks(loop, chunk_fn, states, k)
        if found is None or found.name != FINAL:
            run.save_checkpoint(FINAL, states, history, session, writer)
        progress.update(history, f"evaluating: {config.eval_episodes} greedy episodes per run...")
        eval_key = jax.random.key(config.seeds + 10_000)
        if mesh is not None:
            eval_key = sharding.replicate(eval_key, mesh)
        t0 = time.perf_counter()
        evaluate = evaluator(trainer, mesh, bitwise)
        eval_returns = sharding.to_host(evaluate(states, eval_key))
        eval_seconds = time.perf_counter() - t0
    finally:
        progress.stop()
    history = {name: np.concatenate(parts, axis=2) for name, parts in history.items()}
    summary = summaries.summarize(config, history, eval_returns, states, session)
    summary["eval_seconds"] = round(eval_seconds, 3)  # its compile included
    summary["eval_share"] = round(eval_seconds / max(summary["train_seconds"], 1e-9), 3)
    summary["devices"] = 1 if mesh is None else mesh.size
    summary["bitwise"] = bitwise
    summary["host"] = host()
    if writer:
        run.write_summary(summary)
        summaries.plot_curves(config, history, run)
    return summary


@dataclasses.dataclass
class ChunkLoop:
    """What the host keeps between compiled chunks: the run, its history and its session."""

    config: Config
    options: TrainOptions
    run: RunDir
    history: dict
    """Metric name -> the chunks' arrays so far (updated in place)."""
    session: dict
    """Chunks done, their end times, compile seconds, resumes (updated in place)."""
    progress: Progress
    reported: set
    """The failures already reported (non-finite losses), so each is said once."""


def _train_chunks(loop: ChunkLoop, chunk_fn, states, k):
    """Run chunks until the budget is spent, writing metrics and checkpoints between them;
    returns the states."""
    config, options, run = loop.config, loop.options, loop.run
    history, session, progress, reported = loop.history, loop.session, loop.progress, loop.reported
    writer = jax.process_index() == 0
    logger = options.logger or NullLogger()
    stop = options.stop or Stop()  # one never installed asks for nothing
    chunks = config.iterations // config.chunk_iterations
    train_seconds = session["chunk_ends"][-1] if session["chunk_ends"] else 0.0
    try:
        with run.metrics_writer(writer) as log:  # processes other than 0 write nothing
            for chunk in range(session["chunks_done"], chunks):
                t0 = time.perf_counter()
                states, metrics = chunk_fn(states, k)
                metrics = sharding.to_host(metrics)
                train_seconds += time.perf_counter() - t0
                session["chunk_ends"].append(train_seconds)
                session["chunks_done"] = chunk + 1
                for name, value in metrics.items():
                    history.setdefault(name, []).append(value)
                first = chunk * config.chunk_iterations + 1
                log.write(summaries.metric_lines(config, metrics, train_seconds, first))
                logger.log(config, metrics, train_seconds)
                failure = metrics["failure"][..., -1]
                reported = summaries.report_failures(config, failure, reported)
                progress.update(history, summaries.status(metrics, train_seconds))
                last = chunk + 1 == chunks or budget_spent(config, history)
                due = options.checkpoint_every and (chunk + 1) % options.checkpoint_every == 0
                # Across hosts all stop together: the checkpoint is a collective save.
                stopping = not last and sharding.any_process(stop.requested(chunk + 1))
                if not last and (due or stopping):
                    name = f"chunk_{chunk + 1:05d}"
                    run.save_checkpoint(name, states, history, session, writer)
                solving = config.solved_return is not None  # runs may stop early
                if stopping:
                    known = chunks if _counted_budget(config) is None and not solving else None
                    raise Interrupted(stop.signum or signal.SIGINT, chunk + 1, known)
                if last:
                    break
    finally:
        logger.close()
    return states


def budget_spent(config: Config, history: dict) -> bool:
    """With a `steps` budget (or under schedule "steps" an `episodes` one), or with
    `solved_return`: whether every run has stopped by the last chunk in `history`, at its
    budget, solved, or frozen by the non-finite guard."""
    counted = _counted_budget(config)
    if (counted is None and config.solved_return is None) or not history.get("failure"):
        return False
    stopped = history["failure"][-1][..., -1] != 0
    if counted is not None:
        name, budget = counted
        stopped = stopped | (history[name][-1][..., -1] >= budget)
    if config.solved_return is not None:
        stopped = stopped | (history["greedy_return"][-1][..., -1] >= config.solved_return)
    return bool(stopped.all())


def _counted_budget(config: Config) -> tuple[str, int] | None:
    """The budget runs stop at as they reach it, `(metric, budget)`; None where the number
    of iterations is the budget (schedule "episodes" without `steps`)."""
    if config.steps is not None:
        return "env_steps", config.steps
    if config.schedule == "steps":
        return "episodes", config.episodes
    return None


class Progress:
    """Live display (rich) of the budget spent, moving return, LD, throughput and the phase
    (compiling, training, evaluating), or nothing when quiet."""

    def __init__(self, config: Config, quiet: bool):
        self.config, self.quiet = config, quiet
        if quiet:
            return
        from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn
        from rich.progress import Progress as RichProgress

        unit = "episodes" if config.steps is None else "env steps"
        self.bar = RichProgress(
            TextColumn(f"[bold]{unit}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TextColumn("{task.fields[status]}"),
        )
        total = config.iterations * config.workers if config.steps is None else config.steps
        if config.steps is None and config.schedule == "steps":
            total = config.episodes
        self.task = self.bar.add_task("train", total=total, status="compiling...")
        self.bar.start()

    def update(self, history: dict, status: str) -> None:
        """Show the budget spent by the chunks in `history` (per run: episodes, or the mean
        env steps over runs, capped at the budget) and `status`."""
        if self.quiet:
            return
        counted = _counted_budget(self.config)
        if counted is None:
            iterations = sum(part.shape[2] for part in history.get("episodes", []))
            spent = iterations * self.config.workers
        elif history.get(counted[0]):
            name, budget = counted
            spent = int(np.minimum(history[name][-1][..., -1], budget).mean())
        else:
            spent = 0
        self.bar.update(self.task, completed=spent, status=status)

    def stop(self) -> None:
        if not self.quiet:
            self.bar.stop()
