"""Optional metric sinks beside metrics.jsonl (which is always written).

A logger is fed each chunk's metrics exactly as `run.metric_lines` sees them: a dict of numpy
arrays `[K, S, N, ...]` (K values, seeds, iterations of the chunk).
"""

from __future__ import annotations

import os
import secrets
import socket
import sys
import time
from pathlib import Path
from typing import Protocol
from urllib.parse import urlparse

import numpy as np

from ldn_jax.config import Config
from ldn_jax.host.run_dir import RunDir

LOGGERS = ("none", "tensorboard", "wandb")

STEP_METRICS = ("iteration", "episodes")
"""Counters, not curves: `episodes` is the x axis (TensorBoard's global step)."""


def tag_prefix(config: Config, point: int, seed: int) -> str:
    """`seed{S}_k{K}` (`seed`: the index in the batch, S: the seed), and in a sweep
    `_{field}={value}` for each swept field (e.g. `seed0_k1_agent.actor_lr=0.0003`): the part
    of a metric's name that names its run."""
    values = config.points[point]
    return f"seed{config.first_seed + seed}_k{values['k']:g}" + "".join(
        f"_{name}={values[name]:g}" for name, _ in config.sweep
    )


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

    Tags read `seed{S}_k{K}/{metric}` (e.g. `seed0_k1/moving_return`; a sweep adds its values,
    `tag_prefix`); the global step is the
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
                prefix = tag_prefix(config, ki, seed)
                for i in range(n_iter):
                    step = int(metrics["episodes"][ki, seed, i])
                    for name in names:
                        value = float(metrics[name][ki, seed, i])
                        if np.isfinite(value):  # ld_mean is NaN when nothing was imagined
                            self.writer.add_scalar(f"{prefix}/{name}", value, step, walltime)
        self.writer.flush()

    def close(self) -> None:
        self.writer.close()


class WandbLogger:
    """Weights & Biases: one wandb run per training run, under `RUN_DIR/wandb/`.

    Keys read like TensorBoard's tags, `seed{S}_k{K}/{metric}`, every metric that holds one
    value per iteration (metrics.jsonl's, losses included), each plotted against its own
    seed's `seed{S}_k{K}/episodes` (wandb's `define_metric`); wandb's step is the host's
    iteration. The config is the run's config. A resumed training run continues the same
    wandb run (its id is kept in `wandb/run-id`).

    Mode: `WANDB_MODE` where it is set (online, offline, disabled: wandb's own); otherwise
    online when there is a login and wandb's server answers, else offline with one line on
    stderr saying how to upload later (`wandb sync`).
    """

    def __init__(self, run_dir: Path, config: Config, project: str | None = None):
        import wandb  # optional extra: ldn-jax[wandb]

        self.wandb = wandb
        run = RunDir(run_dir)
        run.wandb_dir.mkdir(parents=True, exist_ok=True)
        id_file = run.wandb_dir / "run-id"
        run_id = id_file.read_text().strip() if id_file.exists() else secrets.token_hex(4)
        id_file.write_text(run_id + "\n")
        mode = os.environ.get("WANDB_MODE") or self._mode(run.wandb_dir)
        self.run = wandb.init(
            project=project or os.environ.get("WANDB_PROJECT") or "ldn-jax",
            name=run.path.name,
            id=run_id,
            resume="allow",
            dir=str(run.path),
            config=config.to_dict(),
            mode=mode,
            settings=wandb.Settings(console="off", silent=True, disable_git=True),
        )
        self.defined: set[str] = set()

    def _mode(self, wandb_dir: Path) -> str:
        host = urlparse(os.environ.get("WANDB_BASE_URL", "https://api.wandb.ai")).hostname
        logged_in = self.wandb.login(prompt=False, verify=False)
        if logged_in and _reachable(host):
            return "online"
        why = f"{host} unreachable" if logged_in else "no wandb login"
        print(
            f"wandb: {why}, logging offline under {wandb_dir} (upload later: wandb sync "
            f"{wandb_dir}/offline-run-*)",
            file=sys.stderr,
        )
        return "offline"

    def log(self, config: Config, metrics: dict[str, np.ndarray], wall_seconds: float) -> None:
        n_k, seeds, n_iter = metrics["iteration"].shape
        names = [n for n, v in metrics.items() if np.ndim(v) == 3 and n != "iteration"]
        for i in range(n_iter):
            row = {"train_seconds": wall_seconds}
            for ki in range(n_k):
                for seed in range(seeds):
                    prefix = tag_prefix(config, ki, seed)
                    if prefix not in self.defined:
                        self.run.define_metric(f"{prefix}/*", step_metric=f"{prefix}/episodes")
                        self.defined.add(prefix)
                    for name in names:
                        value = float(metrics[name][ki, seed, i])
                        if np.isfinite(value):  # ld_mean is NaN when nothing was imagined
                            row[f"{prefix}/{name}"] = value
            self.run.log(row, step=int(metrics["iteration"][..., i].max()))

    def close(self) -> None:
        self.run.finish()


def _reachable(host: str | None, timeout: float = 3.0) -> bool:
    try:
        socket.create_connection((host, 443), timeout=timeout).close()
    except (OSError, TypeError):
        return False
    return True


def make_logger(name: str, run_dir: Path, config: Config, project: str | None = None) -> Logger:
    """The logger called `name` (one of `LOGGERS`) writing under `run_dir`; `project`: the
    wandb project.

    Raises ValueError for an unknown name or a missing optional dependency.
    """
    if name == "none":
        return NullLogger()
    if name == "wandb":
        try:
            return WandbLogger(run_dir, config, project)
        except ImportError:
            raise ValueError("--logger wandb needs wandb: pip install 'ldn-jax[wandb]'") from None
    if name == "tensorboard":
        try:
            return TensorBoardLogger(run_dir)
        except ImportError:
            raise ValueError(
                "--logger tensorboard needs tensorboardX: pip install 'ldn-jax[tensorboard]'"
            ) from None
    raise ValueError(f"unknown logger {name!r}; valid: {', '.join(LOGGERS)}")
