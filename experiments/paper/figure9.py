"""Figure 9: the learning-degree gain K in {0.5, 1, 2} (eq. 6) for MBRL-LDN, one vmapped run
per env (every K shares the seeds' initialisations): cartpole-v2, and the six MuJoCo tasks
(the CPU scale at short budgets).

    python -m experiments.paper.figure9 [--scale cpu|cpu-full|paper] [--smoke] [--results DIR]

Writes figure9.json, figure9.csv and figure9.png (per env: learning curves per K, and episodes
to threshold per K, or the final moving return where the env has no threshold) into
DIR/figure9/.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from experiments.paper import cache, common
from ldn_jax.host.plots import band_panel

K_VALUES = (0.5, 1.0, 2.0)
LISTS = ("k", "final_moving_return", "episodes_to_threshold", "final_moving_returns")
"""Row fields left out of figure9.csv (per-seed lists, and what the CSV spells apart)."""


def rows(entry: dict) -> list[dict]:
    history = cache.load_history(entry["dir"])
    out = []
    for ki, k in enumerate(entry["config"].k):
        runs = [r for r in entry["summary"]["runs"] if r["k"] == k]
        episodes = [r["episodes_to_threshold"] for r in runs]
        final = [r["final_moving_return"] for r in runs]
        out.append(
            {
                "k": k,
                **common.describe(episodes),
                "final_moving_return": common.describe(final),
                "final_moving_return_mean": float(np.nanmean(history["moving_return"][ki, :, -1])),
                "imagined_steps_per_seed": float(history["imagined_steps"][ki, :, -1].mean()),
                "ld_mean_last_iterations": float(np.nanmean(history["ld_mean"][ki, :, -10:])),
                "episodes_to_threshold": episodes,
                "final_moving_returns": final,
            }
        )
    return out


def panel(entry: dict) -> dict:
    return {
        "env": entry["env"],
        "seeds": entry["config"].seeds,
        "episodes": entry["config"].episodes,
        "steps": entry["config"].steps,
        "budget": cache.budget_text(entry["config"]),
        "train_seconds": entry["summary"]["train_seconds"],
        "compile_seconds": entry["summary"]["compile_seconds"],
        "threshold": entry["summary"]["threshold"],
        "rows": rows(entry),
    }


def figure(entries: list[dict], panels: list[dict], path: Path) -> None:
    fig, axes = plt.subplots(len(panels), 2, figsize=(11, 4 * len(panels)), dpi=120, squeeze=False)
    for (left, right), entry, data in zip(axes, entries, panels, strict=True):
        history = cache.load_history(entry["dir"])
        episodes = history["episodes"][0, 0]
        threshold = data["threshold"]
        curves = {
            f"K={row['k']:g}": (episodes, history["moving_return"][ki])
            for ki, row in enumerate(data["rows"])
        }
        title = f"MBRL-LDN on {data['env']} ({data['seeds']} seeds, mean and 95% band)"
        band_panel(left, curves, title, threshold)
        for ki, row in enumerate(data["rows"]):
            key = "episodes_to_threshold" if threshold is not None else "final_moving_returns"
            values = [v for v in row[key] if v is not None]
            if values:
                right.boxplot([values], positions=[ki], widths=0.5, showfliers=False)
                right.plot(ki + np.linspace(-0.12, 0.12, len(values)), values, ".", alpha=0.6)
        if threshold is not None:
            right.set_ylabel(f"episodes to moving return {threshold:g}")
            ticks = [f"K={r['k']:g}\n{r['reached']}/{r['runs']}" for r in data["rows"]]
        else:
            right.set_ylabel(f"moving return after {data['budget']}")
            ticks = [f"K={r['k']:g}" for r in data["rows"]]
        right.set_xticks(range(len(data["rows"])), ticks)
        right.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    scale, results = common.parse_args(argv, __doc__)
    entries = []
    for env in (scale.ld_env, *scale.ablation_envs):
        entries += cache.collect_runs((env,), ("ldn",), scale, results, k=K_VALUES)
    done = [e for e in entries if e["status"] == "done"]
    panels = [panel(e) for e in done]
    pending = [{"env": e["env"], "reason": e["reason"]} for e in entries if e not in done]
    out = common.out_dir(results, "figure9")
    record = {**common.scale_record(scale), "algo": "ldn", "panels": panels, "pending": pending}
    common.write_json(out / "figure9.json", record)
    common.write_csv(
        out / "figure9.csv",
        [
            {
                "env": p["env"],
                "k": r["k"],
                **{k: v for k, v in r.items() if k not in LISTS},
                "final_moving_return_sd": r["final_moving_return"]["sd"],
            }
            for p in panels
            for r in p["rows"]
        ],
    )
    figure(done, panels, out / "figure9.png")
    print(f"wrote {out}/figure9.json, figure9.csv, figure9.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
