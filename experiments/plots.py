"""Figures written into run directories."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from ldn_jax.metrics import mean_band


def learning_curves(
    curves: dict[str, tuple[np.ndarray, np.ndarray]],
    path: Path,
    title: str,
    threshold: float | None = None,
) -> None:
    """One line per label: moving return vs real episodes, mean and 95% band over seeds.

    `curves[label] = (episodes [T], moving_return [S, T])`.
    """
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=120)
    for label, (episodes, returns) in curves.items():
        mean, low, high = mean_band(returns)
        (line,) = ax.plot(episodes, mean, label=f"{label} ({returns.shape[0]} seeds)")
        ax.fill_between(episodes, low, high, color=line.get_color(), alpha=0.2, linewidth=0)
    if threshold is not None:
        ax.axhline(threshold, color="grey", linestyle="--", linewidth=1, label="threshold")
    ax.set_xlabel("real episodes (summed over workers)")
    ax.set_ylabel("moving return")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
