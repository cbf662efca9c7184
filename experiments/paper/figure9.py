"""Figure 9: the learning-degree gain K in {0.5, 1, 2} (eq. 6) for MBRL-LDN on cartpole-v2
and the six MuJoCo tasks (the CPU scale at short budgets). Per env, K = 1 is the MBRL-LDN run
the other results read (Table 4's on MuJoCo, Table 2's and Figure 5's on CartPole: the same
config, trained once), and K = 0.5 and 2 are one vmapped run of their own. Seed s starts from
key s at every K, so the three K share their initialisations as in one vmapped run.

    python -m experiments.paper.figure9 [--scale cpu|cpu-full|paper] [--smoke] [--results DIR]
        [--report]

`--report` trains nothing: an env with a run that is not finished is pending, saying how far
that run got.
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

PARTS = ((1.0,), (0.5, 2.0))
"""The runs Figure 9 reads per env: K = 1, shared with the other results, then its own."""
LISTS = ("k", "final_moving_return", "episodes_to_threshold", "final_moving_returns")
"""Row fields left out of figure9.csv (per-seed lists, and what the CSV spells apart)."""


def rows(entries: list[dict]) -> list[dict]:
    """One row per K, in K order, from the env's runs (`PARTS`)."""
    out = []
    for entry in entries:
        history = cache.load_history(entry["dir"])
        for ki, k in enumerate(entry["config"].k):
            runs = [r for r in entry["summary"]["runs"] if r["k"] == k]
            episodes = [r["episodes_to_threshold"] for r in runs]
            final = [r["final_moving_return"] for r in runs]
            moving = history["moving_return"][ki, :, -1]
            out.append(
                {
                    "k": k,
                    **common.describe(episodes),
                    "final_moving_return": common.describe(final),
                    "final_moving_return_mean": float(np.nanmean(moving)),
                    "episodes_per_seed": float(history["episodes"][ki, :, -1].mean()),
                    "imagined_steps_per_seed": float(history["imagined_steps"][ki, :, -1].mean()),
                    "ld_mean_last_iterations": float(np.nanmean(history["ld_mean"][ki, :, -10:])),
                    "episodes_to_threshold": episodes,
                    "final_moving_returns": final,
                }
            )
    return sorted(out, key=lambda row: row["k"])


def panel(entries: list[dict]) -> dict:
    """The env's panel. Its seconds are those of its own run: the K = 1 run is counted with
    the result it is shared with (Table 4 on MuJoCo)."""
    shared, own = entries
    return {
        "env": own["env"],
        "seeds": own["config"].seeds,
        "episodes": own["config"].episodes,
        "steps": own["config"].steps,
        "budget": cache.budget_text(own["config"]),
        "train_seconds": own["summary"]["train_seconds"],
        "compile_seconds": own["summary"]["compile_seconds"],
        "shared_k": list(shared["config"].k),
        "threshold": own["summary"]["threshold"],
        "rows": rows(entries),
    }


def figure(envs: list[list[dict]], panels: list[dict], path: Path) -> None:
    fig, axes = plt.subplots(len(panels), 2, figsize=(11, 4 * len(panels)), dpi=120, squeeze=False)
    for (left, right), entries, data in zip(axes, envs, panels, strict=True):
        threshold = data["threshold"]
        curves = {}
        for entry in entries:
            history = cache.load_history(entry["dir"])
            for ki, k in enumerate(entry["config"].k):
                curves[k] = (history["episodes"][ki], history["moving_return"][ki])
        curves = {f"K={k:g}": curves[k] for k in sorted(curves)}
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
    report, argv = common.take_flag(argv, "--report")
    scale, results = common.parse_args(argv, __doc__)
    done, pending = [], []
    for env in (scale.ld_env, *scale.ablation_envs):
        entries = []
        for k in PARTS:
            entries += cache.collect_runs((env,), ("ldn",), scale, results, k, not report)
        stopped = [e for e in entries if e["status"] != "done"]
        if stopped:
            pending.append({"env": env, "reason": stopped[0]["reason"]})
        else:
            done.append(entries)
    panels = [panel(entries) for entries in done]
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
    sys.exit(common.script(main))
