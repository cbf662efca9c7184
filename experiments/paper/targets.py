"""The MuJoCo targets at the default budgets: every algorithm on inverted_pendulum, the user's
halfcheetah command, and PPO on halfcheetah.

    python -m experiments.paper.targets [--scale cpu|cpu-full|paper] [--smoke] [--results DIR]
        [--runs ENV-ALGO,...]

Not a table of the paper: what a user gets from the defaults (`ldn_jax.presets.TASKS`), checked
against the targets the project set itself.
- inverted_pendulum, each of the six algorithms, 5 seeds, K = 1: a moving return >= 900 on at
  least 4 of 5 seeds within the default budget, in under 15 minutes of training.
- halfcheetah, `--algo ldn --seeds 10` (10 seeds x K in {0.5, 1, 2}): under 30 minutes end to
  end, and the mean moving return rises by at least 1,000 from the first iteration to the end.
- halfcheetah, `--algo ppo`, 5 seeds: a mean final moving return >= 2,000 by 1M steps.
At the smoke scale the runs take the scale's budgets instead (and halfcheetah is left
pending). Writes targets.json and targets.png into DIR/targets/.

`--runs` (e.g. `halfcheetah-ppo`) trains and measures those runs only and keeps every other
row of the earlier targets.json as it was, with the date it was measured; the curves are
redrawn only when every row's run is on this machine.
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
from pathlib import Path

import numpy as np

from experiments.paper import cache, common, locomotion
from ldn_jax.config import from_preset, validate
from ldn_jax.host.metrics import run_crossing
from ldn_jax.host.run_dir import RunDir

PENDULUM_ALGOS = ("a2c", "a2c-model", "ldn", "ppo", "ppo-model", "ppo-ldn")
PENDULUM_LEVEL = 900.0
PENDULUM_SEEDS = 4  # of 5
PENDULUM_SECONDS = 15 * 60
CHEETAH_RISE = 1000.0
CHEETAH_SECONDS = 30 * 60
CHEETAH_PPO = 2000.0

RUNS = (
    *(("inverted_pendulum", algo, 5, (1.0,)) for algo in PENDULUM_ALGOS),
    ("halfcheetah", "ldn", 10, (0.5, 1.0, 2.0)),
    ("halfcheetah", "ppo", 5, None),
)
"""(env, algo, seeds, K) of each run, as a user would start it (None: the default K, the
first one for a model-free learner)."""


def run_config(scale: common.Scale, env: str, algo: str, seeds: int, k: tuple[float, ...]):
    """The run at its default budget, or at the smoke scale's (None: not run there)."""
    if scale.name != "smoke":
        chosen = {} if k is None else {"k": k}
        return validate(from_preset("paper", env=env, algo=algo, seeds=seeds, **chosen))
    if env not in scale.mujoco_budgets:
        return None
    return common.run_config(scale, env, algo)


def run_dir(results: Path, scale: common.Scale, config) -> Path:
    """Beside the tables' runs; at the default budgets under their own names, since the
    tables' runs of the same env and algorithm have shorter budgets. PPO on a locomotion task
    is the locomotion study's run (the same config), trained once for both. The default
    budgets do not depend on the scale: every scale but smoke keeps them in the cpu scale's
    folder."""
    if scale.name == "smoke":
        return cache.run_dir(results, scale, config)
    if config.algo == "ppo" and config.env in locomotion.ZOO:
        return locomotion.run_dir(results, config.env, config.seeds)
    out = cache.run_dir(results, common.SCALES["cpu"], config)
    return out.with_name("targets-" + out.name)


def pendulum_row(entry: dict) -> dict:
    history = cache.load_history(entry["dir"])
    summary = entry["summary"]
    after = history["moving_after"][0]  # [S, N, W]: after each episode, in completion order
    reach = []
    for seed in range(after.shape[0]):
        crossing = run_crossing(history, (0, seed), PENDULUM_LEVEL)
        reach.append(None if crossing is None else crossing[1])
    highest = np.nanmax(after.reshape(after.shape[0], -1), axis=-1)
    reached = sum(r is not None for r in reach)
    seconds = summary["train_seconds"]
    return {
        "env": entry["env"],
        "algo": entry["algo"],
        "status": "done",
        "budget": cache.budget_text(entry["config"]),
        "seeds": len(reach),
        "reached": reached,
        "steps_to_level": reach,
        "highest": [round(float(h), 1) for h in highest],
        "final_moving_return": [r["final_moving_return"] for r in summary["runs"]],
        "eval_return": [r["eval_return"] for r in summary["runs"]],
        "train_seconds": seconds,
        "compile_seconds": summary["compile_seconds"],
        "met": reached >= PENDULUM_SEEDS and seconds < PENDULUM_SECONDS,
    }


def cheetah_row(entry: dict) -> dict:
    history = cache.load_history(entry["dir"])
    summary = entry["summary"]
    moving = history["moving_return"]  # [K, S, N]
    mean = np.nanmean(moving.reshape(-1, moving.shape[-1]), axis=0)
    finals = [r["final_moving_return"] for r in summary["runs"]]
    wall = summary["train_seconds"] + summary["compile_seconds"] + summary["eval_seconds"]
    row = {
        "env": entry["env"],
        "algo": entry["algo"],
        "status": "done",
        "budget": cache.budget_text(entry["config"]),
        "seeds": entry["config"].seeds,
        "k": list(entry["config"].k),
        "first_mean_moving_return": float(mean[0]),
        "final_mean_moving_return": float(np.mean(finals)),
        "final_moving_return": finals,
        "eval_return": [r["eval_return"] for r in summary["runs"]],
        "train_seconds": summary["train_seconds"],
        "compile_seconds": summary["compile_seconds"],
        "wall_seconds": wall,
    }
    if entry["algo"] == "ldn":
        rise = row["final_mean_moving_return"] - row["first_mean_moving_return"]
        row["met"] = rise >= CHEETAH_RISE and wall < CHEETAH_SECONDS
    else:
        row["met"] = row["final_mean_moving_return"] >= CHEETAH_PPO
    return row


def curves(entries: list[dict], path: Path) -> None:
    """One panel per run: mean moving return and 95% band over its seeds (and K) against the
    mean real env steps, with the target's level dashed."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    from ldn_jax.host.plots import band_panel

    done = [e for e in entries if e["status"] == "done"]
    if not done:
        return
    cols = 4
    rows = -(-len(done) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.4 * rows), dpi=110, squeeze=False)
    for ax, entry in zip(axes.flat, done, strict=False):
        history = cache.load_history(entry["dir"])
        moving = history["moving_return"]
        steps = history["env_steps"].reshape(-1, moving.shape[-1]).mean(axis=0)
        label = common.PAPER_ALGOS.get(entry["algo"], entry["algo"])
        level = PENDULUM_LEVEL if entry["env"] == "inverted_pendulum" else None
        band_panel(
            ax,
            {label: (steps, moving.reshape(-1, moving.shape[-1]))},
            f"{entry['env']} {entry['algo']}",
            level,
            "target",
            legend_size=7,
        )
        ax.set_xlabel("real env steps (mean over seeds)")
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1000:,.0f}k"))
    for ax in list(axes.flat)[len(done) :]:
        ax.axis("off")
    fig.suptitle("MuJoCo at the default budgets", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _names() -> list[str]:
    return [f"{env}-{algo}" for env, algo, _, _ in RUNS]


def parse_runs(argv: list[str] | None) -> tuple[set[str] | None, list[str]]:
    """`--runs` (None: every run) and the arguments left for `common.parse_args`."""
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--runs", default=None)
    args, rest = parser.parse_known_args(sys.argv[1:] if argv is None else argv)
    if args.runs is None:
        return None, rest
    chosen = {name.strip() for name in args.runs.split(",") if name.strip()}
    unknown = sorted(chosen - set(_names()))
    if unknown or not chosen:
        _refuse(
            f"--runs: unknown {', '.join(unknown) or '(none given)'}; "
            f"choose among {', '.join(_names())}"
        )
    return chosen, rest


def _refuse(message: str) -> None:
    """Bad input: one line on stderr, exit code 2 (as argparse does)."""
    print(f"targets: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def _earlier(record: dict) -> dict[str, dict]:
    """The rows of an earlier targets.json by run name, each with the date it was measured."""
    date = record.get("machine", {}).get("date")
    return {f"{row['env']}-{row['algo']}": {"date": date, **row} for row in record.get("rows", [])}


def _finished(run: Path) -> str:
    """The day a run finished training (its summary file's), as the result files date it."""
    stamp = RunDir(run).summary_file.stat().st_mtime
    return datetime.datetime.fromtimestamp(stamp, datetime.UTC).date().isoformat()


def main(argv: list[str] | None = None) -> int:
    chosen, rest = parse_runs(argv)
    scale, results = common.parse_args(rest, __doc__)
    out = common.out_dir(results, "targets")
    earlier_record = {}
    if chosen is not None:
        if not (out / "targets.json").is_file():
            _refuse(f"--runs keeps the other rows of {out / 'targets.json'}, which is not there")
        earlier_record = json.loads((out / "targets.json").read_text())
        if earlier_record.get("scale") != scale.name:
            _refuse(f"--runs: {out / 'targets.json'} is of scale {earlier_record.get('scale')}")
    earlier = _earlier(earlier_record)
    record = common.scale_record(scale)
    entries, table, drawn = [], [], True
    for env, algo, seeds, k in RUNS:
        name = f"{env}-{algo}"
        if chosen is not None and name not in chosen:
            if name not in earlier:
                _refuse(f"--runs: no earlier row for {name} in {out / 'targets.json'}")
            table.append(earlier[name])
            drawn = False
            continue
        config = run_config(scale, env, algo, seeds, k)
        if config is None:
            table.append({"env": env, "algo": algo, "status": "pending"})
            continue
        run = run_dir(results, scale, config)
        entry = {"env": env, "algo": algo, "status": "done", "dir": run, "config": config}
        entry["summary"] = cache.ensure_run(config, run)
        entries.append(entry)
        row = pendulum_row(entry) if env == "inverted_pendulum" else cheetah_row(entry)
        table.append({"date": _finished(run), **row})
    if drawn:
        curves(entries, out / "targets.png")
        record["curves_date"] = record["machine"]["date"]
    else:
        record["curves_date"] = earlier_record.get("curves_date", earlier_record["machine"]["date"])
    common.write_json(out / "targets.json", {**record, "rows": table})
    met = sum(bool(r.get("met")) for r in table)
    drew = "targets.png" if drawn else "not targets.png (rows kept from earlier runs)"
    print(f"wrote {out}/targets.json and {drew} ({met}/{len(table)} targets met)")
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
