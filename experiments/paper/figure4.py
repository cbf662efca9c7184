"""Figure 4: learning curves on CartPole v0/v1/v2 (moving return vs real episodes, mean and
95% band over seeds), A2C vs A2C-Model vs MBRL-LDN, from the Table 2 runs.

    python -m experiments.paper.figure4 [--scale cpu|cpu-full|paper] [--smoke] [--results DIR]

Writes figure4.png and figure4.csv (per env, algo and logged point: episodes, mean, band)
into DIR/figure4/.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from experiments.paper import cache, common, table2
from ldn_jax.host.metrics import mean_band
from ldn_jax.host.plots import band_panel

MAX_POINTS = 200
"""Points per curve in figure4.csv (evenly thinned; the figure uses every iteration)."""


def curves(entries: list[dict]) -> dict[str, dict[str, tuple[np.ndarray, np.ndarray]]]:
    """`{env: {algo: (episodes [N], moving_return [S, N])}}` of the finished runs."""
    out: dict[str, dict] = {}
    for entry in entries:
        if entry["status"] == "done":
            history = cache.load_history(entry["dir"])
            episodes = history["episodes"][0, 0]
            out.setdefault(entry["env"], {})[entry["algo"]] = (
                episodes,
                history["moving_return"][0],
            )
    return out


def figure(curves: dict, thresholds: dict[str, float], path: Path) -> None:
    envs = list(curves)
    fig, axes = plt.subplots(1, len(envs), figsize=(4.6 * len(envs), 3.8), dpi=120, squeeze=False)
    for ax, env in zip(axes[0], envs, strict=True):
        named = {common.PAPER_ALGOS.get(a, a): curve for a, curve in curves[env].items()}
        band_panel(ax, named, env, thresholds[env], legend_size=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def table(curves: dict) -> list[dict]:
    rows = []
    for env, by_algo in curves.items():
        for algo, (episodes, returns) in by_algo.items():
            mean, low, high = mean_band(returns)
            keep = np.unique(np.linspace(0, len(episodes) - 1, MAX_POINTS).round().astype(int))
            for i in keep:
                rows.append(
                    {
                        "env": env,
                        "algo": algo,
                        "episodes": int(episodes[i]),
                        "mean": float(mean[i]),
                        "low95": float(low[i]),
                        "high95": float(high[i]),
                    }
                )
    return rows


def main(argv: list[str] | None = None) -> int:
    scale, results = common.parse_args(argv, __doc__)
    entries = table2.runs(scale, results)
    thresholds = {e["env"]: e["summary"]["threshold"] for e in entries if e["status"] == "done"}
    found = curves(entries)
    out = common.out_dir(results, "figure4")
    figure(found, thresholds, out / "figure4.png")
    common.write_csv(out / "figure4.csv", table(found))
    print(f"wrote {out}/figure4.png, figure4.csv")
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
