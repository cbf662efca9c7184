"""Table 2 and Figure 6: real episodes until the moving return reaches the threshold
(150 on CartPole v0/v1, 100 on v2), A2C vs A2C-Model vs MBRL-LDN, paper preset, K = 1.

    python -m experiments.paper.table2 [--scale cpu|cpu-full|paper] [--smoke] [--results DIR]

Writes table2.json, table2.csv and figure6.png into DIR/table2/. Its runs are shared with
table3.py and figure4.py (and figure5.py reads the cartpole-v2 ldn one).
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from experiments.paper import cache, common

ALGOS = ("a2c", "a2c-model", "ldn")


def runs(scale: common.Scale, results: Path) -> list[dict]:
    """The runs of Tables 2 and 3 and Figure 4 (trained once, reused by the three scripts)."""
    return cache.collect_runs(scale.cartpole_envs, ALGOS, scale, results)


def rows(entries: list[dict]) -> list[dict]:
    out = []
    for entry in entries:
        env, algo = entry["env"], entry["algo"]
        paper = common.PAPER_TABLE2.get((algo, env), (None, None))
        row = {"env": env, "algo": algo, "paper_algo": common.PAPER_ALGOS.get(algo, algo)}
        row["status"] = entry["status"]
        if entry["status"] == "done":
            summary = entry["summary"]
            episodes = [r["episodes_to_threshold"] for r in summary["runs"]]
            row.update(threshold=summary["threshold"], **common.describe(episodes))
            row["episodes_to_threshold"] = episodes
        row.update(paper_mean=paper[0], paper_sd=paper[1])
        out.append(row)
    return out


def figure6(rows: list[dict], path: Path) -> None:
    """Box plot of episodes to threshold per env and algorithm (the paper's Figure 6), with
    each seed as a dot and the paper's mean +- s.d. beside each box."""
    done = [r for r in rows if r["status"] == "done"]
    envs = list(dict.fromkeys(r["env"] for r in done))
    fig, axes = plt.subplots(1, len(envs), figsize=(4.2 * len(envs), 4), dpi=120, squeeze=False)
    for ax, env in zip(axes[0], envs, strict=True):
        here = [r for r in done if r["env"] == env]
        for i, row in enumerate(here):
            values = [v for v in row["episodes_to_threshold"] if v is not None]
            if values:
                ax.boxplot([values], positions=[i], widths=0.5, showfliers=False)
                jitter = np.linspace(-0.12, 0.12, len(values))
                ax.plot(i + jitter, values, ".", color="C0", alpha=0.6)
            if row["paper_mean"] is not None:
                ax.errorbar(
                    i + 0.38, row["paper_mean"], yerr=row["paper_sd"], fmt="D", color="C3", ms=4
                )
        ax.set_xticks(
            range(len(here)),
            [f"{r['paper_algo']}\n{r['reached']}/{r['runs']}" for r in here],
            fontsize=8,
        )
        ax.set_title(f"{env} (threshold {here[0]['threshold']:g})")
        ax.set_ylabel("episodes to threshold")
        ax.grid(alpha=0.3, axis="y")
    axes[0][0].plot([], [], "D", color="C3", ms=4, label="paper mean ± s.d.")
    axes[0][0].plot([], [], ".", color="C0", label="ours, one dot per seed")
    axes[0][0].legend(fontsize=7, loc="upper right")
    fig.suptitle("Episodes to threshold (x labels: runs that reached it)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    scale, results = common.parse_args(argv, __doc__)
    table = rows(runs(scale, results))
    out = common.out_dir(results, "table2")
    common.write_json(out / "table2.json", {**common.scale_record(scale), "k": 1.0, "rows": table})
    flat = [{k: v for k, v in r.items() if k != "episodes_to_threshold"} for r in table]
    common.write_csv(out / "table2.csv", flat)
    figure6(table, out / "figure6.png")
    print(f"wrote {out}/table2.json, table2.csv, figure6.png")
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
