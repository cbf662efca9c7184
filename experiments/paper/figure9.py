"""Figure 9: the learning-degree gain K in {0.5, 1, 2} (eq. 6) for MBRL-LDN on cartpole-v2,
as one vmapped run (every K shares the seeds' initialisations).

    python experiments/paper/figure9.py [--scale cpu|paper] [--smoke] [--results DIR]

Writes figure9.json, figure9.csv and figure9.png (learning curves per K, and episodes to
threshold per K) into DIR/figure9/.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import matplotlib.pyplot as plt
import numpy as np

from experiments.paper import common
from ldn_jax.metrics import mean_band

K_VALUES = (0.5, 1.0, 2.0)


def rows(entry: dict) -> list[dict]:
    history = common.load_history(entry["dir"])
    out = []
    for ki, k in enumerate(entry["config"].k):
        runs = [r for r in entry["summary"]["runs"] if r["k"] == k]
        episodes = [r["episodes_to_threshold"] for r in runs]
        out.append(
            {
                "k": k,
                **common.describe(episodes),
                "final_moving_return_mean": float(np.nanmean(history["moving_return"][ki, :, -1])),
                "imagined_steps_per_seed": float(history["imagined_steps"][ki, :, -1].mean()),
                "ld_mean_last_iterations": float(np.nanmean(history["ld_mean"][ki, :, -10:])),
                "episodes_to_threshold": episodes,
            }
        )
    return out


def figure(entry: dict, table: list[dict], path: Path) -> None:
    history = common.load_history(entry["dir"])
    episodes = history["episodes"][0, 0]
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4), dpi=120)
    for ki, row in enumerate(table):
        mean, low, high = mean_band(history["moving_return"][ki])
        (line,) = left.plot(episodes, mean, label=f"K={row['k']:g}")
        left.fill_between(episodes, low, high, color=line.get_color(), alpha=0.2, linewidth=0)
        values = [v for v in row["episodes_to_threshold"] if v is not None]
        if values:
            right.boxplot([values], positions=[ki], widths=0.5, showfliers=False)
            right.plot(ki + np.linspace(-0.12, 0.12, len(values)), values, ".", alpha=0.6)
    threshold = entry["summary"]["threshold"]
    left.axhline(threshold, color="grey", linestyle="--", linewidth=1, label="threshold")
    left.set_xlabel("real episodes (summed over workers)")
    left.set_ylabel("moving return")
    left.legend(fontsize=8)
    left.grid(alpha=0.3)
    right.set_xticks(
        range(len(table)), [f"K={r['k']:g}\n{r['reached']}/{r['runs']}" for r in table]
    )
    right.set_ylabel(f"episodes to moving return {threshold:g}")
    right.grid(alpha=0.3, axis="y")
    fig.suptitle(f"MBRL-LDN on {entry['env']}: the gain K (mean and 95% band)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    scale, results = common.parse_args(argv, __doc__)
    (entry,) = common.collect_runs((scale.ld_env,), ("ldn",), scale, results, k=K_VALUES)
    table = rows(entry)
    out = common.out_dir(results, "figure9")
    record = {**common.scale_record(scale), "env": scale.ld_env, "algo": "ldn", "rows": table}
    common.write_json(out / "figure9.json", record)
    common.write_csv(
        out / "figure9.csv",
        [{k: v for k, v in r.items() if k != "episodes_to_threshold"} for r in table],
    )
    figure(entry, table, out / "figure9.png")
    print(f"wrote {out}/figure9.json, figure9.csv, figure9.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
