"""Optional metric sinks beside metrics.jsonl (which is always written).

A logger is fed each chunk's metrics exactly as `run.metric_lines` sees them: a dict of numpy
arrays `[K, S, N, ...]` (K values, seeds, iterations of the chunk).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Protocol

import numpy as np

from ldn_jax.config import Config
from ldn_jax.run_dir import RunDir

LOGGERS = ("none", "tensorboard")

STEP_METRICS = ("iteration", "episodes")
"""Counters, not curves: `episodes` is the x axis (TensorBoard's global step)."""


class Logger(Protocol):
    def log(self, config: Config, metrics: dict[str, np.ndarray], wall_seconds: float) -> None:
        """Record one chunk's metrics `[K, S, N, ...]`; `wall_seconds`: training time so far."""
        ...

    def close(self) -> None: ...


class NullLogger:
    def log(self, config: Config, metrics: dict[str, np.ndarray], wall_seconds: float) -> None:
        pass

    def close(self) -> None:
        pass


class TensorBoardLogger:
    """Scalars into `RUN_DIR/tensorboard/`, one tag per metric per seed and K.

    Tags read `seed{S}_k{K}/{metric}` (e.g. `seed0_k1/moving_return`); the global step is the
    real episode count, as in metrics.jsonl and curves.png. Every metric that holds one value
    per iteration is written; per-episode arrays (`returns`, `lengths`, ...) are not. The event
    wall time is the logger's start plus training seconds, so TensorBoard's "relative" axis
    shows training time without compilation.
    """

    def __init__(self, run_dir: Path):
        from tensorboardX import SummaryWriter  # optional extra: ldn-jax[tensorboard]

        self.log_dir = RunDir(run_dir).tensorboard_dir
        self.writer = SummaryWriter(str(self.log_dir))
        self.start = time.time()

    def log(self, config: Config, metrics: dict[str, np.ndarray], wall_seconds: float) -> None:
        n_k, seeds, n_iter = metrics["iteration"].shape
        names = [n for n, v in metrics.items() if np.ndim(v) == 3 and n not in STEP_METRICS]
        walltime = self.start + wall_seconds
        for ki in range(n_k):
            for seed in range(seeds):
                prefix = f"seed{seed}_k{config.k[ki]:g}"
                for i in range(n_iter):
                    step = int(metrics["episodes"][ki, seed, i])
                    for name in names:
                        value = float(metrics[name][ki, seed, i])
                        if np.isfinite(value):  # ld_mean is NaN when nothing was imagined
                            self.writer.add_scalar(f"{prefix}/{name}", value, step, walltime)
        self.writer.flush()

    def close(self) -> None:
        self.writer.close()


def make_logger(name: str, run_dir: Path) -> Logger:
    """The logger called `name` (one of `LOGGERS`) writing under `run_dir`.

    Raises ValueError for an unknown name or a missing optional dependency.
    """
    if name == "none":
        return NullLogger()
    if name == "tensorboard":
        try:
            return TensorBoardLogger(run_dir)
        except ImportError:
            raise ValueError(
                "--logger tensorboard needs tensorboardX: pip install 'ldn-jax[tensorboard]'"
            ) from None
    raise ValueError(f"unknown logger {name!r}; valid: {', '.join(LOGGERS)}")
