"""Figures: learning curves written into run directories, and comparisons across runs."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ldn_jax.config import Config
from ldn_jax.host import stats
from ldn_jax.host.metrics import mean_band
from ldn_jax.host.run_dir import RunDir


def pyplot():
    """matplotlib's pyplot on the file-only Agg backend, imported when a figure is drawn (it
    takes a third of a second: a command that draws nothing does not pay it)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def band_panel(
    ax,
    curves: dict[str, tuple[np.ndarray, np.ndarray]],
    title: str | None = None,
    level: float | None = None,
    level_label: str = "threshold",
    legend_size: int = 8,
) -> None:
    """The one panel every learning-curve figure draws: per label, moving return vs real
    episodes, mean and 95% band over seeds (`curves[label] = (episodes [S, T] or [T], returns
    [S, T])`), and a dashed line at `level` if given.

    Per-seed episodes are drawn at their mean over seeds: a seed that reached its step budget
    early holds its last episode count and return while the others go on, so one seed's count
    would stand still and draw the others' last iterations as a vertical line."""
    for label, (episodes, returns) in curves.items():
        episodes = np.asarray(episodes, float)
        episodes = episodes.mean(axis=0) if episodes.ndim == 2 else episodes
        mean, low, high = mean_band(returns)
        (line,) = ax.plot(episodes, mean, label=f"{label} ({returns.shape[0]} seeds)")
        ax.fill_between(episodes, low, high, color=line.get_color(), alpha=0.2, linewidth=0)
    if level is not None:
        ax.axhline(level, color="grey", linestyle="--", linewidth=1, label=level_label)
    if title is not None:
        ax.set_title(title)
    ax.set_xlabel("real episodes (summed over workers; mean over seeds)")
    ax.set_ylabel("moving return")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=legend_size)


def learning_curves(
    curves: dict[str, tuple[np.ndarray, np.ndarray]],
    path: Path,
    title: str,
    threshold: float | None = None,
) -> None:
    """One figure of one `band_panel`, written to `path`."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=120)
    band_panel(ax, curves, title, threshold)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def run_curves(run_dir: Path, name: str) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], Config]:
    """Moving return vs episodes of one run directory: `{label: (episodes [S, T], returns
    [S, T])}` with a label `name: algo K=k` per K (K left out where it does not matter; a sweep's
    values added), and its config.

    Raises ValueError with a one-line message for a missing or unreadable run.
    """
    if not run_dir.is_dir():
        raise ValueError(f"no such run directory: {run_dir}")
    run = RunDir(run_dir)
    config = run.read_config()  # RunDirError (a ValueError) names what is wrong
    try:
        lines = run.read_metrics()
    except FileNotFoundError:
        raise ValueError(f"{run_dir} has no metrics yet (no metrics.jsonl)") from None
    except (OSError, UnicodeDecodeError, KeyError, TypeError) as error:
        raise ValueError(f"{run_dir}: unreadable metrics.jsonl ({error})") from None
    points: dict[tuple, dict[int, dict[int, tuple]]] = {}
    for line in lines:
        point = (line["k"], tuple(line.get("sweep", {}).items()))
        logged = points.setdefault(point, {}).setdefault(line["seed"], {})
        logged[line["iteration"]] = (line["episodes"], line["moving_return"])
    show_k = len(config.k) > 1 or config.uses_k
    curves = {}
    for (k, sweep), by_seed in points.items():
        # Iterations every seed has logged: a run still training may be ahead in some seeds.
        iterations = sorted(set.intersection(*(set(logged) for logged in by_seed.values())))
        if not iterations:
            continue
        episodes = np.array([[logged[i][0] for i in iterations] for logged in by_seed.values()])
        returns = np.array([[logged[i][1] for i in iterations] for logged in by_seed.values()])
        label = f"{name}: {config.algo}" + (f" K={k:g}" if show_k else "")
        label += "".join(f" {field}={value:g}" for field, value in sweep)
        curves[label] = (episodes, returns)
    if not curves:
        raise ValueError(f"{run_dir} has no metrics yet")
    return curves, config


def compare_runs(run_dirs: list[Path], path: Path) -> None:
    """Overlay runs in one figure (see `learning_curves`), each labelled with the IQM over
    seeds of its last moving return and the bootstrap 95% interval; raises ValueError for a
    bad run."""
    curves, configs = {}, []
    for run_dir in run_dirs:
        run, config = run_curves(run_dir, str(run_dir))
        for name, (episodes, returns) in run.items():
            final = stats.text(stats.estimate(returns[:, -1]))
            curves[f"{name}, last IQM {final}"] = (episodes, returns)
        configs.append(config)
    thresholds = {config.resolved_threshold for config in configs}
    title = " / ".join(dict.fromkeys(config.env for config in configs))
    learning_curves(curves, path, title, thresholds.pop() if len(thresholds) == 1 else None)
