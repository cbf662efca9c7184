"""Table 5: PPO2 vs PPO2-Model vs PPO2-LDN on InvertedPendulum, HalfCheetah and Hopper:
episodes to reach the top.

    python -m experiments.paper.table5 [--scale cpu|cpu-full|paper] [--smoke] [--results DIR]

The paper does not define "the top". Ours, per task: 90% of the highest moving return any
run of the three algorithms reached (`TOP_FRACTION`); a run's episodes to the top count real
episodes until its moving return first reaches it (a run that never does is counted in
*reached*, and REPORT.md's tests count it at the episodes it took: `episodes_per_run`).
Both scales run all three tasks (the CPU scale at short budgets). Writes table5.json,
table5.csv and table5.png into DIR/table5/.
"""

from __future__ import annotations

import sys

import numpy as np

from experiments.paper import cache, common, plots
from ldn_jax.host.metrics import run_crossing

ENVS = ("inverted_pendulum", "halfcheetah", "hopper")
ALGOS = ("ppo", "ppo-model", "ppo-ldn")
TOP_FRACTION = 0.9
SHORT = "runs at --scale paper only (on CPU this task gets a short run, too short to top out)"


def episodes_to(history: dict[str, np.ndarray], level: float) -> list[int | None]:
    """Per seed (K = 1): the global episode at which the moving return first reaches `level`."""
    out = []
    for seed in range(history["moving_after"].shape[1]):
        crossing = run_crossing(history, (0, seed), level)
        out.append(crossing[0] if crossing else None)
    return out


def imagination(history: dict[str, np.ndarray]) -> dict:
    """Imagined steps per seed over the run (their mean, and per seed: `imagined_steps`), the
    mean LD of the last 10 iterations (None for model-free runs), and per seed the learner
    updates made on imagined rows: the history's per-iteration `imagined_updates` (the PPO
    updates on full batches of the imaginary memory that iteration) summed over the run.
    PPO's imaginary memory learns only from full batches: a run may imagine and never learn
    from it. None where the history has no such count (every imagined segment is learnt from
    as it is played)."""
    if "ld_mean" not in history:
        return {
            "imagined_steps_per_seed": 0.0,
            "imagined_steps": None,
            "ld_mean_last_iterations": None,
            "imagined_updates": None,
        }
    updates = None
    if "imagined_updates" in history:
        updates = [int(n) for n in np.nansum(history["imagined_updates"][0], axis=-1)]
    return {
        "imagined_steps_per_seed": float(history["imagined_steps"][0, :, -1].mean()),
        "imagined_steps": [int(n) for n in history["imagined_steps"][0, :, -1]],
        "ld_mean_last_iterations": float(np.nanmean(history["ld_mean"][0, :, -10:])),
        "imagined_updates": updates,
    }


def rows(entries: list[dict]) -> list[dict]:
    histories = {
        (e["env"], e["algo"]): cache.load_history(e["dir"])
        for e in entries
        if e["status"] == "done"
    }
    tops = {}
    for (env, _), history in histories.items():
        best = float(np.nanmax(history["moving_return"]))
        tops[env] = max(tops.get(env, -np.inf), best)
    out = []
    for entry in entries:
        env, algo = entry["env"], entry["algo"]
        paper = common.PAPER_TABLE5.get(env, (None, None, None))[ALGOS.index(algo)]
        row = {"env": env, "algo": algo, "status": entry["status"], "paper": paper}
        if entry["status"] == "done":
            runs = entry["summary"]["runs"]
            top = TOP_FRACTION * tops[env]
            to_top = episodes_to(histories[env, algo], top)
            row.update(
                top=top,
                **common.describe(to_top),
                episodes_to_top=to_top,
                episodes_per_run=[int(n) for n in histories[env, algo]["episodes"][0, :, -1]],
                final_moving_return=common.describe([r["final_moving_return"] for r in runs]),
                **imagination(histories[env, algo]),
                **cache.run_fields(entry),
            )
        else:
            row["reason"] = entry["reason"]
        out.append(row)
    return out


def main(argv: list[str] | None = None) -> int:
    scale, results = common.parse_args(argv, __doc__)
    entries = cache.collect_runs(
        tuple(e for e in ENVS if e in scale.learning_envs), ALGOS, scale, results
    )
    entries += [
        {"env": env, "algo": algo, "status": "pending", "reason": SHORT}
        for env in ENVS
        if env not in scale.learning_envs
        for algo in ALGOS
    ]
    entries.sort(key=lambda e: ENVS.index(e["env"]))
    table = rows(entries)
    out = common.out_dir(results, "table5")
    record = {
        **common.scale_record(scale),
        "seeds": scale.mujoco_seeds,
        "top": f"{TOP_FRACTION:g} x the highest moving return of any run on the task",
        "rows": table,
    }
    common.write_json(out / "table5.json", record)
    lists = ("episodes_to_top", "episodes_per_run", "final_moving_return", "eval_return")
    common.write_csv(
        out / "table5.csv",
        [
            {k: v for k, v in r.items() if k not in lists}
            | {
                "final_moving_return_mean": (r.get("final_moving_return") or {}).get("mean"),
                "eval_return_mean": (r.get("eval_return") or {}).get("mean"),
            }
            for r in table
        ],
    )
    tops = {r["env"]: r["top"] for r in table if r["status"] == "done"}
    plots.mujoco_curves(entries, out / "table5.png", "Table 5: PPO2 family", levels=tops)
    pending = sum(r["status"] == "pending" for r in table)
    print(f"wrote {out}/table5.json, table5.csv, table5.png ({pending}/{len(table)} pending)")
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
