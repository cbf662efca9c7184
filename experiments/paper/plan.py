"""What a scale's MuJoCo results still need: every run of Tables 4 and 5 and Figure 9's MuJoCo
panels, where it stands and what it cost; with `--train`, those runs trained one by one.

    python -m experiments.paper.plan [--scale cpu|cpu-full|paper] [--train] [--results DIR]

A run is *done* (finished in its directory), *record* (its committed record stands in for
it), *partial* (interrupted: resumed from its last checkpoint) or *new* (trained from
scratch). Seconds are the finished runs' training and compile, as measured on the machine
that ran them. `--scale cpu-full` is many hours on 2 cores: this says how far it has come.

`--train` trains the runs that are not finished, in the order listed (Tables 4 and 5 before
Figure 9's runs), each leaving its record, and writes no result file: the
results in DIR stay those of the scale that made them until `make paper SCALE=...` rebuilds
them from the finished runs, in seconds once all are there. Stopped, it resumes. A run that
another process is training (its directory's lock is held) is passed over, so on a machine
with cores to spare two `--train` processes share the list.
"""

from __future__ import annotations

import sys

from rich.console import Console
from rich.table import Table

from experiments.paper import cache, common, figure9, table4, table5
from ldn_jax.host.run_dir import RunDirBusy


def runs(scale: common.Scale) -> list[tuple[str, str, str, tuple[float, ...]]]:
    """(result, env, algo, K) of every MuJoCo run the scale's tables and figure read: Tables
    4 and 5, then Figure 9's K = 0.5 and 2 (two K per run; its K = 1 is Table 4's run)."""
    out = [("table4", env, algo, (1.0,)) for env in table4.ENVS for algo in table4.ALGOS]
    out += [("table5", env, algo, (1.0,)) for env in table5.ENVS for algo in table5.ALGOS]
    out += [("figure9", env, "ldn", figure9.PARTS[-1]) for env in scale.ablation_envs]
    return [run for run in out if run[1] in common.MUJOCO]


def rows(scale: common.Scale, results) -> list[dict]:
    out = []
    for result, env, algo, k in runs(scale):
        row = {"result": result, "env": env, "algo": algo, "k": k}
        try:
            config = common.run_config(scale, env, algo, k)
        except ValueError:
            out.append(row | {"state": "not at this scale"})
            continue
        where = cache.run_dir(results, scale, config)
        row |= {"seeds": config.seeds, "budget": cache.budget_text(config), "dir": where}
        out.append(row | cache.progress(config, where))
    return out


def summary(table: list[dict]) -> str:
    counts = {
        state: sum(r["state"] == state for r in table)
        for state in ("done", "record", "partial", "new", "not at this scale")
    }
    ours = len(table) - counts["not at this scale"]
    minutes = sum(r.get("seconds", 0.0) for r in table) / 60
    return (
        f"{counts['done'] + counts['record']} of {ours} runs finished ({counts['record']} from "
        f"records), {minutes:,.0f} min of training and compile measured; "
        f"{counts['partial']} partial, {counts['new']} to train from scratch"
        + (
            f"; {counts['not at this scale']} not at this scale"
            if counts["not at this scale"]
            else ""
        )
    )


def train(scale: common.Scale, results) -> None:
    """Train every run of `rows` that is not finished, in order (records left behind). A run
    another process is training is passed over, so two of these can share the list."""
    for row in rows(scale, results):
        if row["state"] in ("partial", "new"):
            config = common.run_config(scale, row["env"], row["algo"], row["k"])
            try:
                cache.ensure_run(config, row["dir"])
            except RunDirBusy as busy:
                print(f"passed over: {busy}", flush=True)


def main(argv: list[str] | None = None) -> int:
    training, argv = common.take_flag(argv, "--train")
    scale, results = common.parse_args(argv, __doc__)
    if training:
        train(scale, results)
    table = rows(scale, results)
    view = Table(title=f"MuJoCo runs of --scale {scale.name}", title_justify="left")
    for column in ("result", "env", "algo", "K", "seeds", "budget", "state", "s / steps done"):
        view.add_column(column, justify="right" if column.startswith("s") else "left")
    for r in table:
        done = (
            f"{r['seconds']:,.0f} s"
            if "seconds" in r
            else f"{r['steps']:,} steps"
            if "steps" in r
            else ""
        )
        view.add_row(
            r["result"],
            r["env"],
            r["algo"],
            ",".join(f"{k:g}" for k in r["k"]),
            str(r.get("seeds", "")),
            r.get("budget", ""),
            r["state"],
            done,
        )
    console = Console(width=110)
    console.print(view)
    console.print(summary(table))
    return 0


if __name__ == "__main__":
    sys.exit(main())
