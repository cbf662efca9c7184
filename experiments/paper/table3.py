"""Table 3: wall-clock seconds until the moving return reaches the threshold, from the Table 2
runs (trained by table2.py, or here if missing).

    python -m experiments.paper.table3 [--scale cpu|cpu-full|paper] [--smoke] [--results DIR]

Our seconds are those of one compiled program running every seed of a run at once (vmapped),
compilation excluded and reported apart: `seconds` is when a seed crossed, in the wall time of
the whole batch; `per_seed_seconds` divides it by the number of seeds (what one seed would cost
if vmapping were free, a lower bound, not a measurement). Writes table3.json, table3.csv and
table3.png into DIR/table3/.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from experiments.paper import common, table2


def rows(entries: list[dict]) -> list[dict]:
    out = []
    for entry in entries:
        env, algo = entry["env"], entry["algo"]
        row = {"env": env, "algo": algo, "paper_algo": common.PAPER_ALGOS.get(algo, algo)}
        row["status"] = entry["status"]
        if entry["status"] == "done":
            summary, seeds = entry["summary"], entry["config"].seeds
            seconds = [r["seconds_to_threshold"] for r in summary["runs"]]
            steps = [r["env_steps_to_threshold"] for r in summary["runs"]]
            stats = common.describe(seconds)
            per_seed = {
                f"per_seed_{name}": None if stats[name] is None else stats[name] / seeds
                for name in ("mean", "sd")
            }
            row.update(
                threshold=summary["threshold"],
                seeds=seeds,
                **stats,
                **per_seed,
                env_steps_mean=common.describe(steps)["mean"],
                compile_seconds=summary["compile_seconds"],
                train_seconds=summary["train_seconds"],
                env_steps_per_second=summary["env_steps_per_second"],
                seconds_to_threshold=seconds,
            )
        row["paper_seconds"] = common.PAPER_TABLE3.get((algo, env))
        out.append(row)
    return out


def figure(rows: list[dict], path: Path) -> None:
    """Bars: mean seconds to threshold (whole vmapped batch) per env and algorithm."""
    done = [r for r in rows if r["status"] == "done"]
    envs = list(dict.fromkeys(r["env"] for r in done))
    algos = list(dict.fromkeys(r["algo"] for r in done))
    fig, ax = plt.subplots(figsize=(7, 4), dpi=120)
    width = 0.8 / max(len(algos), 1)
    for j, algo in enumerate(algos):
        here = {r["env"]: r for r in done if r["algo"] == algo}
        means = [here[e]["mean"] if e in here and here[e]["mean"] is not None else 0 for e in envs]
        sds = [(here[e]["sd"] or 0) if e in here else 0 for e in envs]
        x = np.arange(len(envs)) + (j - (len(algos) - 1) / 2) * width
        ax.bar(x, means, width, yerr=sds, label=common.PAPER_ALGOS.get(algo, algo), capsize=3)
    ax.set_xticks(range(len(envs)), envs)
    ax.set_ylabel(f"seconds to threshold ({done[0]['seeds']} seeds vmapped at once)")
    ax.set_title("Wall-clock seconds to threshold (compilation excluded), mean ± s.d.")
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    scale, results = common.parse_args(argv, __doc__)
    table = rows(table2.runs(scale, results))
    out = common.out_dir(results, "table3")
    common.write_json(out / "table3.json", {**common.scale_record(scale), "rows": table})
    flat = [{k: v for k, v in r.items() if k != "seconds_to_threshold"} for r in table]
    common.write_csv(out / "table3.csv", flat)
    figure(table, out / "table3.png")
    print(f"wrote {out}/table3.json, table3.csv, table3.png")
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
