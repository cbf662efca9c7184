"""Table 4: total moving reward on six MuJoCo tasks, A2C-Model vs MBRL-LDN.

    python -m experiments.paper.table4 [--scale cpu|cpu-full|paper] [--smoke] [--results DIR]
        [--report]

"Total moving reward" is read as the final moving return (the paper's numbers exceed what
some tasks can score in 1,000 steps, so compare the two algorithms, not the values). Both
scales run all six tasks: the CPU scale at short budgets (`common.MUJOCO_CPU_BUDGETS`),
`--scale paper` at 4,000 episodes. `--report` trains nothing: a run that is not finished
(another process may be training it) is a pending row. Writes table4.json, table4.csv and
table4.png (learning curves per task) into DIR/table4/.
"""

from __future__ import annotations

import sys

from experiments.paper import cache, common, plots

ENVS = ("ant", "halfcheetah", "hopper", "reacher", "walker2d", "inverted_pendulum")
ALGOS = ("a2c-model", "ldn")


def rows(entries: list[dict]) -> list[dict]:
    out = []
    for entry in entries:
        env, algo = entry["env"], entry["algo"]
        paper = common.PAPER_TABLE4.get(env, (None, None))[ALGOS.index(algo)]
        row = {"env": env, "algo": algo, "status": entry["status"], "paper": paper}
        if entry["status"] == "done":
            runs = entry["summary"]["runs"]
            final = [r["final_moving_return"] for r in runs]
            row.update(common.describe(final))
            row.update(final_moving_returns=final, **cache.run_fields(entry))
            summary = entry["summary"]
            row["imagined_share"] = summary.get("imagined_steps", 0) / summary["env_steps"]
        else:
            row["reason"] = entry["reason"]
        out.append(row)
    return out


def plain_a3c(results, entries: list[dict]) -> dict[str, list[float]]:
    """Per task whose Table 4 runs are the family study's (the same configs: the tasks of a
    1M-step default budget and the paper's step limit, `cache.run_dir`), plain A3C's final
    moving returns from that study's finished run of the same config, or its record; trains
    nothing."""
    out = {}
    for entry in entries:
        if entry["algo"] != "ldn" or entry["status"] != "done":
            continue
        env, seeds = entry["env"], entry["config"].seeds
        if entry["dir"] != cache.family_run_dir(results, env, "ldn", seeds):
            continue
        run = cache.family_run_dir(results, env, "a2c", seeds)
        if cache.progress(common.family_config(env, "a2c", seeds), run)["state"] == "new":
            continue
        summary = cache.finished_summary(run)
        if summary is not None:
            out[env] = [r["final_moving_return"] for r in summary["runs"]]
    return out


def main(argv: list[str] | None = None) -> int:
    report, argv = common.take_flag(argv, "--report")
    scale, results = common.parse_args(argv, __doc__)
    entries = cache.collect_runs(ENVS, ALGOS, scale, results, train=not report)
    table = rows(entries)
    out = common.out_dir(results, "table4")
    record = {
        **common.scale_record(scale),
        "seeds": scale.mujoco_seeds,
        "metric": "final moving return",
        "rows": table,
        "plain_a3c": plain_a3c(results, entries),
    }
    common.write_json(out / "table4.json", record)
    common.write_csv(
        out / "table4.csv",
        [
            {k: v for k, v in r.items() if k not in ("final_moving_returns", "eval_return")}
            | {"eval_return_mean": (r.get("eval_return") or {}).get("mean")}
            for r in table
        ],
    )
    plots.mujoco_curves(entries, out / "table4.png", "Table 4: A3C-Model vs MBRL-LDN")
    pending = sum(r["status"] == "pending" for r in table)
    print(f"wrote {out}/table4.json, table4.csv, table4.png ({pending}/{len(table)} pending)")
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
