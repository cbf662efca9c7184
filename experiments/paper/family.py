"""The A2C family on the six MuJoCo tasks at their default budgets.

    python -m experiments.paper.family [--envs ENV,...] [--algos ALGO,...] [--seeds N]
        [--results DIR] [--report]

Not a table of the paper: what `--algo a2c`, `a2c-model` and `ldn` give on each MuJoCo task
at its default budget and constants (`ldn_jax.presets.TASKS`), as `ldn-jax --env ENV --algo
ALGO --seeds 5 --k 1` starts them. Per run: the final moving return and the trainer's greedy
evaluation after training (10 episodes) per seed with their IQM [95% interval], the imagined
steps per seed (a model-based run whose learning degree never let it imagine is an A2C run
with a model beside it, and the table says so), and the wall time; one panel of curves per
task. PPO's rows are the locomotion study's.

Writes DIR/family/family.json, family.md (REPORT.md's section "The A2C family at the default
budgets") and family.png; runs are cached in DIR/runs/family/ and resumed (inverted_pendulum's
are the targets' runs, the same configs), and rows not run this time are kept.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

from experiments.paper import cache, common, locomotion, targets
from ldn_jax.host import stats

ENVS = ("inverted_pendulum", "halfcheetah", "hopper", "walker2d", "ant", "reacher")
ALGOS = common.FAMILY_ALGOS
TITLE = "The A2C family at the default budgets"


def config_of(env: str, algo: str, seeds: int):
    """K = 1 (the paper's MuJoCo runs'), as the targets' inverted_pendulum rows have it."""
    return common.family_config(env, algo, seeds)


def run_dir(results: Path, env: str, algo: str, seeds: int) -> Path:
    """inverted_pendulum's runs at 5 seeds are the targets' (the same configs, trained once)."""
    config = config_of(env, algo, seeds)
    if env == "inverted_pendulum" and seeds == 5:
        return targets.run_dir(results, common.SCALES["cpu"], config)
    return cache.family_run_dir(results, env, algo, seeds)


def standardised(agent: dict) -> str:
    """What the run standardises of its inputs, from its config's `agent` section."""
    parts = [
        name
        for name, on in (
            ("observations", agent["normalize_obs"]),
            ("rewards", agent["normalize_reward"]),
        )
        if on
    ]
    return " and ".join(parts) or "nothing"


def _standardised_of(*dirs: Path | None) -> str | None:
    """`standardised` of the first of `dirs` that holds a config; None where none does."""
    for where in dirs:
        if where is not None and (file := where / "config.json").is_file():
            return standardised(json.loads(file.read_text())["agent"])
    return None


def row_of(env: str, algo: str, out: Path, summary: dict) -> dict:
    runs = summary["runs"]
    history = cache.load_history(out)
    imagined = history["imagined_steps"][0, :, -1] if algo != "a2c" else None
    return {
        "env": env,
        "algo": algo,
        "seeds": len(runs),
        "steps": int(history["env_steps"][0, :, -1].mean()),
        "final_moving_return": [r["final_moving_return"] for r in runs],
        "eval_return": [r["eval_return"] for r in runs],
        "imagined_steps": None if imagined is None else [int(n) for n in imagined],
        "wall_seconds": summary["train_seconds"] + summary["compile_seconds"],
        "diverged": sum(bool(r["diverged"]) for r in runs),
        "curve": locomotion.kept_curve(history),
        "standardised": _standardised_of(out),
    }


def _imagined_text(row: dict) -> str:
    if row["imagined_steps"] is None:
        return "–"
    mean = float(np.mean(row["imagined_steps"]))
    idle = row["imagined_steps"].count(0)
    return f"{mean:,.0f}" + (f" ({idle} of {row['seeds']} seeds none)" if idle else "")


def _default_standardised(env: str, algo: str, seeds: int) -> str:
    return standardised(dataclasses.asdict(config_of(env, algo, seeds).agent))


def section(rows: list[dict]) -> str:
    old = [
        r
        for r in rows
        if r.get("standardised") is not None
        and r["standardised"] != _default_standardised(r["env"], r["algo"], r["seeds"])
    ]
    lines = [
        f"## {TITLE}",
        "",
        "Ours, `python -m experiments.paper.family`: `--algo a2c`, `a2c-model` and `ldn` at "
        "each MuJoCo task's default budget and constants (the native MuJoCo engine, 2 CPU "
        "cores; PPO's rows are in the locomotion study). IQM [95% bootstrap interval] over "
        "seeds; the greedy return is the trainer's own evaluation after training (10 "
        "episodes); imagined steps are per seed over the run (a model-based run that imagined "
        "nothing learnt as A2C does); wall s is the run's training and compile seconds as "
        "the trainer measured them on a shared machine, an upper bound on its cost alone "
        "(docs/logs/tuning-mujoco.md says what ran beside each). Curves: "
        "![family](family/family.png)",
        "",
        "| task | algorithm | real steps, mean | seeds | final moving return | per seed "
        "| greedy return | per seed | imagined steps | diverged | wall s | standardised |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        mark = " (not today's default)" if r in old else ""
        lines.append(
            f"| {r['env']} | {common.PAPER_ALGOS.get(r['algo'], r['algo'])} "
            f"| {r['steps']:,} | {r['seeds']} "
            f"| {stats.text(stats.estimate(r['final_moving_return']))} "
            f"| {', '.join(f'{v:,.0f}' for v in r['final_moving_return'])} "
            f"| {stats.text(stats.estimate(r['eval_return']))} "
            f"| {', '.join(f'{v:,.0f}' for v in r['eval_return'])} "
            f"| {_imagined_text(r)} | {r['diverged']} | {r['wall_seconds']:,.0f} "
            f"| {r.get('standardised') or 'not recorded'}{mark} |"
        )
    have = {(r["env"], r["algo"]) for r in rows}
    missing = [f"{env} {algo}" for env in ENVS for algo in ALGOS if (env, algo) not in have]
    if missing:
        lines += ["", f"Not measured yet: {', '.join(missing)}."]
    if old:
        names = ", ".join(f"{r['env']} {r['algo']}" for r in old)
        lines += [
            "",
            f"Rows trained before their task's default changed ({names}): the column "
            "'standardised' says what they ran with; they are stale until retrained.",
        ]
    return "\n".join(lines) + "\n"


def curves(rows: list[dict], path: Path) -> None:
    """One panel per task: each algorithm's moving return (mean, 95% band over seeds)
    against real env steps."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    from ldn_jax.host.plots import band_panel

    envs = [env for env in ENVS if any(r["env"] == env for r in rows)]
    if not envs:
        return
    cols = min(3, len(envs))
    grid = -(-len(envs) // cols)
    fig, axes = plt.subplots(grid, cols, figsize=(4.4 * cols, 3.5 * grid), dpi=110, squeeze=False)
    for ax, env in zip(axes.flat, envs, strict=False):
        panel = {
            common.PAPER_ALGOS[r["algo"]]: (
                np.asarray(r["curve"]["env_steps"], float),
                np.asarray(r["curve"]["moving_return"], float),
            )
            for r in rows
            if r["env"] == env
        }
        band_panel(ax, panel, env, legend_size=7)
        ax.set_xlabel("real env steps (mean over seeds)")
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1000:,.0f}k"))
    for ax in list(axes.flat)[len(envs) :]:
        ax.axis("off")
    fig.suptitle(TITLE, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _names(text: str, known: tuple[str, ...], flag: str, parser) -> list[str]:
    names = [name.strip() for name in text.split(",") if name.strip()]
    unknown = [name for name in names if name not in known]
    if unknown or not names:
        parser.error(f"{flag}: {', '.join(unknown) or '(none given)'} not in {', '.join(known)}")
    return names


def _write(out: Path, rows: dict) -> None:
    ordered = [rows[e, a] for e in ENVS for a in ALGOS if (e, a) in rows]
    (out / "family.md").write_text(section(ordered))
    common.write_json(out / "family.json", {"machine": common.machine(), "rows": ordered})
    curves(ordered, out / "family.png")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", default=",".join(ENVS))
    parser.add_argument("--algos", default=",".join(ALGOS))
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--results", type=Path, default=common.RESULTS)
    parser.add_argument("--report", action="store_true", help="train nothing; rebuild the files")
    args = parser.parse_args(argv)
    envs = _names(args.envs, ENVS, "--envs", parser)
    algos = _names(args.algos, ALGOS, "--algos", parser)
    out = common.out_dir(args.results, "family")
    record = out / "family.json"
    rows = (
        {(r["env"], r["algo"]): r for r in json.loads(record.read_text())["rows"]}
        if record.exists()
        else {}
    )
    for (env, algo), row in rows.items():  # rows recorded before the column: from their records
        if "standardised" not in row:
            run = run_dir(args.results, env, algo, row["seeds"])
            row["standardised"] = _standardised_of(cache.record_of(run), run)
    if args.report:
        envs = []
    for env in envs:
        for algo in algos:  # the files after each run, so a stopped study keeps what it finished
            run = run_dir(args.results, env, algo, args.seeds)
            summary = cache.ensure_run(config_of(env, algo, args.seeds), run)
            rows[env, algo] = row_of(env, algo, run, summary)
            _write(out, rows)
    _write(out, rows)
    print(f"wrote {out}/family.json, family.md and family.png")
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
