"""`ldn-jax compare`: runs side by side, as the field reports them since Agarwal et al. 2021:
per run (and K) the interquartile mean over seeds with its bootstrap 95% interval of
episodes and env steps to threshold, final moving return and greedy eval return, and the
probability that a seed of each run beats a seed of the first run.

    ldn-jax compare runs/a2c runs/ldn [--json FILE]

Runs of one config on other seeds (a later `--seeds 5 --first-seed 5` beside a run of seeds
0..4) are pooled into one row, "a + b".

Reads each run's summary.json (the per-seed results), nothing else; numpy in, plain data out.
"""

from __future__ import annotations

from pathlib import Path

from ldn_jax import envs
from ldn_jax.host import stats
from ldn_jax.host.run_dir import RunDir, RunDirError

METRICS = {
    "episodes_to_threshold": ("episodes to threshold", True),
    "env_steps_to_threshold": ("env steps to threshold", True),
    "final_moving_return": ("final moving return", False),
    "eval_return": ("greedy eval return", False),
}
"""summary.json's per-seed result -> (its heading, lower is better)."""


def _read(run_dir: Path) -> tuple:
    """`(config, summary)` of a finished run, or ValueError naming what is wrong."""
    if not run_dir.is_dir():
        raise ValueError(f"no such run directory: {run_dir}")
    run = RunDir(run_dir)
    config = run.read_config()  # RunDirError (a ValueError) names what is wrong
    try:
        summary = run.read_summary()
    except FileNotFoundError:
        raise ValueError(f"{run_dir} has no summary.json (training not finished?)") from None
    except ValueError as error:
        raise RunDirError(f"{run_dir}: unreadable summary.json ({error})") from None
    return config, summary


def _pooled(runs: list[tuple]) -> list[tuple]:
    """`(names, config, summary)` per run, where runs of one config on other seeds (`--seeds
    5 --first-seed 5` beside a run of seeds 0..4) are pooled into one entry, in the order
    their first run was given: configs equal but for their seeds and the preset's name they
    started from (a MuJoCo backend "auto" read as what it resolves to here). Runs whose seeds
    overlap stay apart."""
    groups: list[list] = []
    for name, config, summary in runs:
        same = {**config.to_dict(), "seeds": None, "first_seed": None, "preset": None}
        if same.get("backend") == "auto" and config.env in envs.mujoco.TASKS:
            same["backend"] = envs.mujoco.resolve_backend("auto")  # as the CLI records it
        seeds = set(range(config.first_seed, config.first_seed + config.seeds))
        for group in groups:
            if group[0] == same and not group[1] & seeds:
                group[1] |= seeds
                group[2].append((name, config, summary))
                break
        else:
            groups.append([same, seeds, [(name, config, summary)]])
    out = []
    for _, _, members in groups:
        names = " + ".join(name for name, _, _ in members)
        runs_of = [r for _, _, summary in members for r in summary["runs"]]
        out.append((names, members[0][1], {**members[0][2], "runs": runs_of}))
    return out


def rows(run_dirs: list[Path]) -> list[dict]:
    """One row per run and point (K, and a sweep's values): its name (the directory's, or
    its path where two share a name), env, algo, K, the point's name, seeds, how many
    reached the threshold, and per metric the per-seed values and `stats.estimate` of
    them. Runs of one config on other seeds are one row ("a + b", `_pooled`)."""
    out = []
    names = [d.name for d in run_dirs]
    runs = [(d.name if names.count(d.name) == 1 else str(d), *_read(d)) for d in run_dirs]
    for run_name, config, summary in _pooled(runs):
        for index, point in enumerate(config.points):
            k, sweep = point["k"], {n: v for n, v in point.items() if n != "k"}
            seeds = [r for r in summary["runs"] if r["k"] == k and r.get("sweep", {}) == sweep]
            row = {
                "run": run_name,
                "env": config.env,
                "algo": config.algo,
                "k": k if config.uses_k else None,
                "point": config.point_name(index),
                "seeds": len(seeds),
                "threshold": summary.get("threshold"),
                "reached": sum(r["episodes_to_threshold"] is not None for r in seeds),
            }
            for name in METRICS:
                values = [r[name] for r in seeds if r.get(name) is not None]
                row[name] = {"values": values, **stats.estimate(values)}
            out.append(row)
    return out


def improvements(table: list[dict]) -> list[dict]:
    """Per row after the first on the same env: the probability of improvement over the
    first row of that env on each metric (lower counts as better for the to-threshold
    ones), with its bootstrap interval."""
    out = []
    for row in table:
        base = next(r for r in table if r["env"] == row["env"])
        if base is row:
            continue
        entry = {"run": row["run"], "point": row["point"], "baseline": base["run"]}
        entry["baseline_point"] = base["point"]
        for name, (_, lower) in METRICS.items():
            entry[name] = stats.improvement(
                row[name]["values"], base[name]["values"], lower_is_better=lower
            )
        out.append(entry)
    return out


def label(row: dict) -> str:
    point = f" {row['point']}" if row["point"] else ""
    return f"{row['run']} ({row['algo']}{point})"


def render(table: list[dict], better: list[dict]) -> list[str]:
    """The comparison as markdown tables (fit for a terminal and for notes); a metric no
    run has (no threshold on MuJoCo) is left out."""
    shown = [name for name in METRICS if any(row[name]["n"] for row in table)]
    header = ["run", "env", "seeds", "reached", *(METRICS[name][0] for name in shown)]
    lines = [
        "IQM over seeds [bootstrap 95% interval]; to-threshold columns over the seeds "
        "that reached it.",
        "",
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
    ]
    for row in table:
        cells = [label(row), row["env"], str(row["seeds"]), f"{row['reached']}/{row['seeds']}"]
        cells += [stats.text(row[name]) for name in shown]
        lines.append("| " + " | ".join(cells) + " |")
    if better:
        lines += [
            "",
            "Probability that a seed of the run beats a seed of the first run on its env "
            "(fewer episodes or steps, higher returns) [bootstrap 95% interval]:",
            "",
            "| run | against | " + " | ".join(METRICS[name][0] for name in shown) + " |",
            "|" + "---|" * (2 + len(shown)),
        ]
        by_run = {(r["run"], r["point"]): r for r in table}
        for entry in better:
            cells = [
                label(by_run[entry["run"], entry["point"]]),
                label(by_run[entry["baseline"], entry["baseline_point"]]),
            ]
            cells += [stats.improvement_text(entry[name]) for name in shown]
            lines.append("| " + " | ".join(cells) + " |")
    return lines
