"""The paper scripts' figures drawn from their cached runs (Tables 4 and 5's curves, the
off-policy studies' curves against real steps)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from experiments.paper.cache import has_history, load_history
from experiments.paper.common import PAPER_ALGOS
from ldn_jax.host.plots import band_panel, pyplot


def mujoco_curves(
    entries: list[dict], path: Path, title: str, levels: dict[str, float] | None = None
) -> None:
    """One panel per finished env: the moving return of each algorithm (mean and 95% band
    over seeds, K = 1), with a dashed line at `levels[env]` if given. Writes nothing when no
    run finished."""
    import matplotlib.pyplot as plt

    done: dict[str, list[dict]] = {}
    for entry in entries:
        if entry["status"] == "done":
            done.setdefault(entry["env"], []).append(entry)
    if not done:
        return
    fig, axes = plt.subplots(1, len(done), figsize=(5 * len(done), 3.8), dpi=120, squeeze=False)
    for ax, (env, runs) in zip(axes[0], done.items(), strict=True):
        curves = {}
        for entry in runs:
            history = load_history(entry["dir"])
            name = PAPER_ALGOS.get(entry["algo"], entry["algo"])
            curves[name] = (history["episodes"][0], history["moving_return"][0])
        level = levels.get(env) if levels else None
        band_panel(ax, curves, env, level, "the top", legend_size=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def smoothed(returns: np.ndarray, window: int) -> np.ndarray:
    """`[S, T]` -> the trailing mean over the last `window` iterations (fewer at the start)."""
    total = np.cumsum(returns, axis=1)
    ahead = np.concatenate([np.zeros_like(total[:, :window]), total[:, :-window]], axis=1)
    counts = np.minimum(np.arange(1, returns.shape[1] + 1), window)
    return (total - ahead) / counts


def step_curves(
    panels: dict[str, dict[str, list[Path]]],
    path: Path,
    title: str,
    levels: dict[str, float] | None = None,
) -> bool:
    """One panel per task (`panels[task][label]`: the run directories, each with its seeds,
    K = 1): the training episodes' return against real steps, per seed the trailing mean
    over a twentieth of the run's iterations, mean and 95% band over all the label's seeds;
    a dashed line at `levels[task]` if given. Runs of one label are cut to the shortest; a
    run with nothing finished to read is left out. Writes nothing without a run; says whether
    it wrote the figure."""
    from matplotlib.ticker import FuncFormatter

    panels = {
        task: {label: [out for out in runs if has_history(out)] for label, runs in labels.items()}
        for task, labels in panels.items()
    }
    panels = {task: labels for task, labels in panels.items() if any(labels.values())}
    if not panels:
        return False
    plt = pyplot()
    width = max(7.0, 5 * len(panels))
    fig, axes = plt.subplots(1, len(panels), figsize=(width, 3.8), dpi=120)
    for ax, (task, labels) in zip(np.atleast_1d(axes), panels.items(), strict=True):
        curves = {}
        for label, runs in labels.items():
            if not runs:
                continue
            histories = [load_history(out) for out in runs]
            length = min(h["env_steps"].shape[-1] for h in histories)
            steps = np.concatenate([h["env_steps"][0, :, :length] for h in histories])
            returns = np.concatenate([h["episode_return"][0, :, :length] for h in histories])
            window = max(1, length // 20)
            curves[label] = (steps, smoothed(returns.astype(float), window))
        level = levels.get(task) if levels else None
        band_panel(ax, curves, task, level, "target", legend_size=7)
        ax.set_xlabel("real steps per seed")
        ax.set_ylabel("training episode return")
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1000:g}k"))
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return True
