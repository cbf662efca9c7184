"""The paper scripts' figures drawn from their cached runs (Tables 4 and 5's curves)."""

from __future__ import annotations

from pathlib import Path

from experiments.paper.cache import load_history
from experiments.paper.common import PAPER_ALGOS
from ldn_jax.host.plots import band_panel


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
