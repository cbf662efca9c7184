"""PPO on the locomotion tasks at the default budget, against rl-baselines3-zoo's PPO.

    python -m experiments.paper.locomotion [--envs ENV,...] [--seeds N] [--results DIR]

Not a table of the paper: what `--algo ppo` gives on halfcheetah, hopper, walker2d, ant and
ant-nocfrc at its default budget (1M real steps, `ldn_jax.presets.TASKS`), as `ldn-jax --env
ENV --algo ppo --seeds 5` starts it, beside the figure users know: the zoo's benchmark, one
tuned SB3 PPO run per task after 1M steps. Per task: the final moving return and the trainer's
greedy evaluation after training (10 episodes) per seed, their IQM [95% interval], the ratio
of the greedy IQM to the zoo's figure, and the wall time.

Writes DIR/locomotion/locomotion.json, locomotion.md (REPORT.md's section "PPO on the
locomotion tasks against the zoo") and locomotion.png; runs are cached in
DIR/runs/locomotion/ and resumed, and rows of tasks not run this time are kept.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from experiments.paper import cache, common
from ldn_jax.config import from_preset, validate
from ldn_jax.host import stats
from ldn_jax.host.run_dir import RunDir

ZOO = {
    "halfcheetah": 5819.0,
    "hopper": 2410.0,
    "walker2d": 3479.0,
    "ant": 1327.0,
    "ant-nocfrc": 1327.0,
}
"""rl-baselines3-zoo's benchmark table (PPO, 1M steps, one run per task, its own tuned
hyperparameters; Ant with the default ones). Its Ant figure is set beside both our ants: it
came from gym's Ant-v3 with all-zero contact forces, which `ant-nocfrc` is in effect."""

TITLE = "PPO on the locomotion tasks against the zoo"

SB3_RUNS = "sb3_zoo_ppo.jsonl"
"""Beside locomotion.json: SB3's PPO with the zoo's constants trained on these cores, one JSON
line per task and seed as `baselines/sb3_ppo.py TASK SEED STEPS` prints it (greedy returns of 5
gymnasium episodes), appended by hand with the date; the 1M-step lines are set beside ours."""


def config_of(env: str, seeds: int):
    return validate(from_preset("paper", env=env, algo="ppo", seeds=seeds))


def row_of(env: str, out: Path, summary: dict) -> dict:
    runs = summary["runs"]
    history = cache.load_history(out)
    evals = [r["eval_return"] for r in runs]
    greedy = stats.estimate(evals)
    return {
        "env": env,
        "seeds": len(runs),
        "steps": int(history["env_steps"][0, :, -1].mean()),
        "final_moving_return": [r["final_moving_return"] for r in runs],
        "eval_return": evals,
        "zoo": ZOO[env],
        "ratio": greedy["iqm"] / ZOO[env],
        "wall_seconds": summary["train_seconds"] + summary["compile_seconds"],
        "diverged": sum(bool(r["diverged"]) for r in runs),
        "curve": kept_curve(history),
    }


CURVE_POINTS = 100
"""Iterations kept of each row's curve in locomotion.json, so that the figure can be drawn
again without the runs (they are not kept in git)."""


def kept_curve(history: dict) -> dict:
    """Every seed's moving return and the mean env steps, at `CURVE_POINTS` iterations."""
    moving, steps = history["moving_return"][0], history["env_steps"][0].mean(axis=0)
    keep = np.unique(np.linspace(0, steps.shape[0] - 1, CURVE_POINTS).round().astype(int))
    return {
        "env_steps": [round(float(x)) for x in steps[keep]],
        "moving_return": [[round(float(x), 1) for x in seed[keep]] for seed in moving],
    }


def sb3_runs(out: Path) -> dict[str, list[dict]]:
    """The 1M-step lines of `SB3_RUNS` in `out`, per task (none if the file is not there)."""
    path, runs = out / SB3_RUNS, {}
    if path.exists():
        for line in path.read_text().splitlines():
            run = json.loads(line)
            if run["steps"] == 1_000_000:
                runs.setdefault(run["task"], []).append(run)
    return runs


def side_by_side(rows: list[dict], sb3: dict[str, list[dict]]) -> list[str]:
    """The lines setting SB3's runs on these cores beside ours, per task both have."""
    both = [r for r in rows if r["env"] in sb3]
    if not both:
        return []
    lines = [
        "Side by side on these cores: SB3's PPO with the zoo's constants for the task "
        f"(`baselines/sb3_ppo.py`, 1M steps; `locomotion/{SB3_RUNS}`), each seed's greedy return "
        "the mean of 5 gymnasium episodes, against ours above; P(ours better) is the chance "
        "that a seed of ours scores above a seed of theirs, with its bootstrap interval.",
        "",
        "| task | SB3 seeds | SB3 greedy, per seed | SB3 IQM | ours IQM | P(ours better) |",
        "|---|---|---|---|---|---|",
    ]
    for r in both:
        theirs = [run["mean"] for run in sorted(sb3[r["env"]], key=lambda run: run["seed"])]
        ours = r["eval_return"]
        lines.append(
            f"| {r['env']} | {len(theirs)} | {', '.join(f'{v:,.0f}' for v in theirs)} "
            f"| {stats.text(stats.estimate(theirs))} | {stats.text(stats.estimate(ours))} "
            f"| {stats.improvement_text(stats.improvement(ours, theirs))} |"
        )
    return [*lines, ""]


def section(rows: list[dict], sb3: dict[str, list[dict]] | None = None) -> str:
    lines = [
        f"## {TITLE}",
        "",
        "Ours, `python -m experiments.paper.locomotion`: `--algo ppo` at its default budget and "
        "constants on each task (the native MuJoCo engine, 2 CPU cores), beside "
        "rl-baselines3-zoo's PPO after 1M steps (one tuned run per task). IQM [95% bootstrap "
        "interval] over seeds; the greedy return is the trainer's own evaluation after "
        "training (10 episodes); the ratio is the greedy IQM over the zoo's figure; a seed whose "
        "parameters went non-finite is frozen at its last finite state and counted as diverged. "
        "Curves: ![locomotion](locomotion/locomotion.png)",
        "",
        "| task | real steps, mean | seeds | final moving return | per seed | greedy return "
        "| per seed | zoo PPO | ratio | diverged | wall s |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['env']} | {r['steps']:,} | {r['seeds']} "
            f"| {stats.text(stats.estimate(r['final_moving_return']))} "
            f"| {', '.join(f'{v:,.0f}' for v in r['final_moving_return'])} "
            f"| {stats.text(stats.estimate(r['eval_return']))} "
            f"| {', '.join(f'{v:,.0f}' for v in r['eval_return'])} "
            f"| {r['zoo']:,.0f} | {r['ratio']:.2f} | {r.get('diverged', 0)} "
            f"| {r['wall_seconds']:,.0f} |"
        )
    met = [r["env"] for r in rows if r["ratio"] >= 1.0]
    missing = [env for env in ZOO if env not in {r["env"] for r in rows}]
    uncurved = [r["env"] for r in rows if "curve" not in r]
    lines += [
        "",
        f"At the zoo's figure or above: {', '.join(met) if met else 'none'} "
        f"({len(met)} of {len(rows)} tasks)."
        + (f" Not measured yet: {', '.join(missing)}." if missing else "")
        + (
            f" Not in the figure (its curve was not kept): {', '.join(uncurved)}."
            if uncurved
            else ""
        ),
        "",
        *side_by_side(rows, sb3 or {}),
    ]
    return "\n".join(lines)


def curves(rows: list[dict], path: Path) -> None:
    """One panel per row with a curve: moving return (mean, 95% band over seeds) against
    real env steps, with the zoo's figure dashed."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    from ldn_jax.host.plots import band_panel

    rows = [r for r in rows if "curve" in r]
    if not rows:
        return
    fig, axes = plt.subplots(1, len(rows), figsize=(4.4 * len(rows), 3.5), dpi=110, squeeze=False)
    for ax, row in zip(axes[0], rows, strict=True):
        steps = np.asarray(row["curve"]["env_steps"], float)
        moving = np.asarray(row["curve"]["moving_return"], float)
        env = row["env"]
        band_panel(ax, {"ppo": (steps, moving)}, env, ZOO[env], "zoo PPO at 1M", legend_size=7)
        ax.set_xlabel("real env steps (mean over seeds)")
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1000:,.0f}k"))
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def run_dir(results: Path, env: str, seeds: int) -> Path:
    """Where the study keeps a task's run (the targets' PPO row reads it too)."""
    return results / "runs" / "locomotion" / f"{env}-ppo-s{seeds}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", default=",".join(ZOO))
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--results", type=Path, default=common.RESULTS)
    args = parser.parse_args(argv)
    envs = args.envs.split(",")
    unknown = [env for env in envs if env not in ZOO]
    if unknown:
        parser.error(f"--envs: {', '.join(unknown)} not in {', '.join(ZOO)}")
    out = common.out_dir(args.results, "locomotion")
    record = out / "locomotion.json"
    rows = {r["env"]: r for r in json.loads(record.read_text())["rows"]} if record.exists() else {}
    for env in envs:  # the files after each task, so a stopped study keeps what it finished
        run = run_dir(args.results, env, args.seeds)
        summary = cache.ensure_run(config_of(env, args.seeds), run)
        rows[env] = row_of(env, run, summary)
        _write(out, record, [rows[env] for env in ZOO if env in rows], args.results)
    print(f"wrote {out}/locomotion.json, locomotion.md and locomotion.png")
    return 0


def _write(out: Path, record: Path, rows: list[dict], results: Path) -> None:
    for row in rows:  # a row recorded before rows kept their curve: from its run, if at hand
        run = run_dir(results, row["env"], row["seeds"])
        if "curve" not in row and RunDir(run).summary_file.exists():
            row["curve"] = kept_curve(cache.load_history(run))
    (out / "locomotion.md").write_text(section(rows, sb3_runs(out)))
    common.write_json(record, {"machine": common.machine(), "rows": rows})
    curves(rows, out / "locomotion.png")


if __name__ == "__main__":
    sys.exit(common.script(main))
