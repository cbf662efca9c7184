"""The A2C family's MuJoCo constants, measured one knob at a time from today's defaults toward
SB3's A2C (the zoo's MuJoCo runs), each arm a vmapped program of 5 seeds.

    python -m experiments.paper.a2c [--tasks TASK,...] [--arms ARM,...] [--steps N]
                                    [--first-seed S] [--report]
    python -m experiments.paper.a2c --user-command

`--user-command` trains (or reuses) the command users start with, `ldn-jax --env halfcheetah
--algo ldn --seeds 10` (10 seeds x K in {0.5, 1, 2}, 1M steps), and replays its 30 greedy
policies in gymnasium into `a2c/user-command.json` and `.md`: the IQM per K with its
interval, and the wall clock.

Each arm is today's task default plus the fields below (each arm adds one knob to the one
before it, unless its entry says otherwise). Trains every run (resumed when interrupted,
reused when finished; records under `records/a2c/`), replays each seed's greedy policy in
gymnasium (10 episodes, `ldn-jax eval`'s) into `a2c/arms/TASK-ARM-sS+5-STEPS.json`
(committed), and `--report` rebuilds `a2c/a2c.md` from those files. Seeds 0-4 choose the
constants (exploratory); the chosen ones are confirmed on fresh seeds under a plan.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from experiments.paper import cache, common
from ldn_jax import presets
from ldn_jax.config import Config, from_preset, validate
from ldn_jax.host import stats

TASKS = ("halfcheetah", "hopper", "walker2d")
SEEDS = 5
EPISODES = 10
STEPS = 300_000
"""The screening budget; the chosen arms run again at 1M (`--steps 1000000`)."""

_OBS = {"agent.normalize_obs": True, "agent.normalize_reward": False}
"""Rewards as they come, said outright: hopper's default standardises them since 2026-12-07,
and each arm keeps the config it trained under."""
_STEPS = {**_OBS, "schedule": "steps"}
_NETS = {
    **_STEPS,
    "agent.hidden_layers": 2,
    "agent.actor_hidden": 64,
    "agent.critic_hidden": 64,
    "agent.activation": "tanh",
    "agent.init": "orthogonal",
    "agent.log_std_init": 0.0,
    "agent.squash_mean": False,
}
_OPTIMISER = {
    **_NETS,
    "a2c.rmsprop": "torch",
    "agent.rmsprop_decay": 0.99,
    "a2c.max_grad_norm": 0.5,
    "a2c.value_coef": 0.5,
    "agent.actor_lr": 7e-4,
    "agent.critic_lr": 7e-4,
}
_N5 = {**_OPTIMISER, "agent.n_steps": 5}
_W1 = {**_N5, "workers": 1}
_PPO = presets.TASKS["halfcheetah"]["learners"]["ppo"]
_PPO_NETS = (
    "agent.hidden_layers",
    "agent.actor_hidden",
    "agent.critic_hidden",
    "agent.activation",
    "agent.init",
    "agent.log_std_init",
)
"""What "wide" takes of PPO's halfcheetah constants: its nets, not its optimiser."""
ARMS: dict[str, dict[str, object]] = {
    "default": {},
    "obs-norm": _OBS,
    "steps": _STEPS,
    "sb3-nets": _NETS,
    "sb3-optimiser": _OPTIMISER,
    "n5": _N5,
    "w1": _W1,
    "sb3": {**_W1, "agent.normalize_reward": True},
    "n5-reward": {**_N5, "agent.normalize_reward": True},
    "obs-reward": {**_OBS, "agent.normalize_reward": True},
    "w16": {**_OBS, "workers": 16},
    "w32": {**_OBS, "workers": 32},
    "log-std": {**_OBS, "agent.log_std_init": -2.0},
    "wide": {**_OBS, **{field: _PPO[field] for field in _PPO_NETS}},
}
"""Arm -> fields over the task's defaults (`--set` names). "sb3" is SB3's A2C under the zoo's
VecNormalize in our knobs: one env, 5 steps per update, 64 x 64 tanh nets with orthogonal
init and a state-free log std from 0, PyTorch's RMSProp (decay 0.99, eps 1e-5) at 7e-4 under
a 0.5 clip, observations and rewards standardised, no entropy bonus; "n5-reward" is the same
on 8 workers; "obs-reward" is "obs-norm" with the rewards standardised too; "w16" and "w32"
are "obs-norm" on 16 and 32 workers (fewer updates of more rows for the same real steps: what
an accelerator's default could use, if it learns as well); "log-std" is "obs-norm" with a
state-free log std from -2 (the zoo's MuJoCo runs), "wide" that on PPO's halfcheetah nets (two
256-unit ReLU layers, PyTorch's fan-in initialiser)."""


def config_of(task: str, arm: str, first_seed: int, steps: int) -> Config:
    config = from_preset(
        "paper", env=task, algo="a2c", seeds=SEEDS, first_seed=first_seed, steps=steps, **ARMS[arm]
    )
    return validate(config)


def run_dir(results: Path, task: str, arm: str, first_seed: int, steps: int) -> Path:
    return results / "runs" / "a2c" / f"{task}-{arm}-s{first_seed}+{SEEDS}-{steps}"


def ensure(task: str, arm: str, args: argparse.Namespace, code: str) -> None:
    config = config_of(task, arm, args.first_seed, args.steps)
    out = run_dir(args.results, task, arm, args.first_seed, args.steps)
    file = common.out_dir(args.results, "a2c/arms") / f"{out.name}.json"
    labels = {"task": task, "arm": arm, "fields": ARMS[arm]}
    cache.ensure_replayed(config, out, file, labels, (code, EPISODES))


def report(results: Path) -> None:
    rows = _scored(results / "a2c" / "arms")
    order = {arm: i for i, arm in enumerate(ARMS)}
    rows.sort(key=lambda r: (r["task"], r["steps"], r["seeds"][0], order.get(r["arm"], 99)))
    lines = [
        "## The A2C family's MuJoCo constants, one knob at a time (`experiments/paper/a2c.py`)",
        "",
        "Greedy return in gymnasium (10 episodes per seed): IQM [95% bootstrap interval] over "
        "the seeds, and each seed's mean. Seeds 0-4 are exploratory (they choose the "
        "constants). halfcheetah's A2C family standardises its observations since 583a1fe, "
        "so the family section's halfcheetah rows predate its default; they are rerun on "
        "fresh seeds under `experiments/plans/a2c.md`.",
        "",
        "| task | steps | seeds | arm | greedy return | per seed | env steps/s | code |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        seeds = f"{r['seeds'][0]}-{r['seeds'][-1]}"
        each = ", ".join(f"{s:,.0f}" for s in r["scores"])
        lines.append(
            f"| {r['task']} | {r['steps']:,} | {seeds} | {r['arm']} | {stats.text(r['score'])} "
            f"| {each} | {r['env_steps_per_second']:,.0f} | {', '.join(r['commits'])} |"
        )
    confirmed = [{**r, **_imagined(results, r)} for r in _scored(results / "a2c" / "confirm")]
    found = confirm_tests(confirmed)
    lines += ["", *confirm_section(confirmed, found)]
    lines += sb3_lines(results, rows, confirmed)
    out = common.out_dir(results, "a2c")
    common.write_json(out / "a2c.json", {"rows": rows, "confirmatory": confirmed, "tests": found})
    (out / "a2c.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out}/a2c.json and a2c.md")


SB3_RUNS = "sb3_a2c.jsonl"
"""SB3's A2C under the zoo's settings, one JSON line per task and seed as
`baselines/sb3_a2c.py TASK SEED STEPS` prints it (with the SB3 version and the load beside it
added when kept), in `a2c/`."""
DEFAULT_ARMS = {"halfcheetah": "obs-norm", "hopper": "obs-reward", "walker2d": "obs-norm"}
"""Each task's arm that is its A2C-family default today (seeds 0-4 chose it)."""


def sb3_lines(results: Path, rows: list[dict], confirmed: list[dict]) -> list[str]:
    """SB3's A2C runs (`SB3_RUNS`) beside ours at the task default and the same budget."""
    file = results / "a2c" / SB3_RUNS
    if not file.exists():
        return []
    runs = [json.loads(line) for line in file.read_text().splitlines() if line.strip()]
    lines = [
        "",
        "### Beside SB3's A2C (`baselines/sb3_a2c.py`, the zoo's MuJoCo settings)",
        "",
        "SB3's: one seed per row, greedy return in gymnasium over its script's 5 episodes. "
        "Ours: `--algo a2c` at the task's default, IQM over 5 seeds (10 episodes each) at "
        "the same budget, on the seeds that chose the default (exploratory) and on the plan's "
        "fresh ones. Steps per second are comparable only between rows run under the same "
        "load.",
        "",
        "| task | steps | SB3 seed | SB3 greedy return | SB3 training s | SB3 env steps/s | "
        "load | ours, seeds 0-4 | ours, seeds 10-14 |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in sorted(runs, key=lambda r: (r["task"], r["steps"], r["seed"])):
        arm = DEFAULT_ARMS.get(r["task"])
        chose = [
            x for x in rows if (x["task"], x["arm"], x["steps"]) == (r["task"], arm, r["steps"])
        ]
        fresh = [
            x
            for x in confirmed
            if (x["task"], x["algo"], x["steps"]) == (r["task"], "a2c", r["steps"])
        ]
        ours = lambda found: stats.text(found[0]["score"]) if found else "–"
        lines.append(
            f"| {r['task']} | {r['steps']:,} | {r['seed']} | {r['mean']:,.0f} | "
            f"{r['train_seconds']:,.0f} | {r['steps'] / r['train_seconds']:,.0f} | "
            f"{r.get('load', '–')} | {ours(chose)} | {ours(fresh)} |"
        )
    return lines


def _scored(folder: Path) -> list[dict]:
    """The files in `folder` replayed in gymnasium, each with its per-seed scores and IQM."""
    return [{**data, "score": stats.estimate(data["scores"])} for data in cache.replayed(folder)]


CONFIRM_SEEDS = 10
"""The plan's fresh seeds (`experiments/plans/a2c.md`): 10-14."""
CONFIRM_ALGOS = ("a2c", "a2c-model", "ldn")
CONFIRM_TASKS = ("halfcheetah", "hopper")
"""The plan's tasks with targets and tests (walker2d's `a2c` is stated only)."""
CONFIRM_TARGETS = {("halfcheetah", "a2c"): 3041.0, ("hopper", "a2c"): 1000.0}
"""The plan's targets for the IQM of the greedy returns (halfcheetah's: the zoo's A2C)."""
COMPARISONS = (("ldn", "a2c"), ("ldn", "a2c-model"))
"""The plan's one-sided tests "a > b" on each of `CONFIRM_TASKS`, Holm over all four."""
ALPHA = 0.05
FEW_IMAGINED = 0.05
"""A model-based run imagining fewer steps than this share of its real ones is said to."""


def _imagined(results: Path, row: dict) -> dict:
    """The steps a confirm run imagined per real step, from its run's summary (or record)."""
    name = f"{row['task']}-{row['algo']}-s{row['seeds'][0]}+{len(row['seeds'])}-{row['steps']}"
    summary = cache.finished_summary(results / "runs" / "a2c" / "confirm" / name)
    if summary is None or not summary.get("env_steps"):
        return {"imagined_per_real": None}
    return {"imagined_per_real": summary["imagined_steps"] / summary["env_steps"]}


def confirm_tests(rows: list[dict]) -> list[dict] | None:
    """The plan's four tests with Holm's correction; None until every run they read has its
    5 seeds replayed."""
    scores = {(r["task"], r["algo"]): r["scores"] for r in rows if len(r["seeds"]) == SEEDS}
    return stats.planned_tests(scores, CONFIRM_TASKS, COMPARISONS, ALPHA, group="task")


def _imagined_text(row: dict) -> str:
    share = row["imagined_per_real"]
    if row["algo"] == "a2c" or share is None:
        return "–"
    few = f" (under {FEW_IMAGINED:.0%} of its real steps)" if share < FEW_IMAGINED else ""
    return f"{share:.2%}{few}"


def _target_text(row: dict) -> str:
    target = CONFIRM_TARGETS.get((row["task"], row["algo"]))
    if target is None:
        return "–"
    met = "met" if row["score"]["iqm"] >= target else "not met"
    return f"{target:,.0f}: {met}"


def confirm_section(rows: list[dict], found: list[dict] | None) -> list[str]:
    """The plan's runs, targets and tests as markdown lines."""
    lines = [
        "The plan's runs on fresh seeds (confirmatory, `experiments/plans/a2c.md`; K = 1, the "
        "task defaults). Imagined: the steps the model imagined per real step, all seeds "
        "together.",
        "",
        "| task | algorithm | steps | seeds | greedy return | per seed | target | imagined "
        "| code |",
        "|---|---|---|---|---|---|---|---|---|",
        *(
            f"| {r['task']} | {r['algo']} | {r['steps']:,} | {r['seeds'][0]}-{r['seeds'][-1]} "
            f"| {stats.text(r['score'])} | {', '.join(f'{s:,.0f}' for s in r['scores'])} "
            f"| {_target_text(r)} | {_imagined_text(r)} | {', '.join(r['commits'])} |"
            for r in rows
        ),
        "",
    ]
    if found is None:
        missing = [
            f"{task} `{algo}`"
            for task in CONFIRM_TASKS
            for algo in CONFIRM_ALGOS
            if not any(r["task"] == task and r["algo"] == algo for r in rows)
        ]
        return [*lines, f"The plan's tests wait for: {', '.join(missing)}."]
    lines += [
        "The plan's tests: one-sided Mann-Whitney U, 5 against 5 seeds; Holm over the four. "
        'P(improvement) with its 95% bootstrap interval; "level" where that interval '
        "contains 0.5.",
        "",
        *stats.tests_table(found, "task", "P(improvement)", ("shown", "not shown at 5 seeds")),
        "",
        "Level: "
        + "; ".join(
            f"{t['task']} `{t['a']}` vs `{t['b']}`: {'yes' if _level(t) else 'no'}" for t in found
        )
        + ".",
    ]
    return lines


def _level(test: dict) -> bool:
    if test["ci95"] is None:
        return False
    low, high = test["ci95"]
    return low <= 0.5 <= high


def confirm(task: str, algo: str, results: Path, code: str) -> None:
    """One of the plan's runs: `ldn-jax --env TASK --algo ALGO --seeds 5 --first-seed 10
    --k 1` at the task's defaults, replayed in gymnasium into `a2c/confirm/`."""
    config = from_preset(
        "paper", env=task, algo=algo, seeds=SEEDS, first_seed=CONFIRM_SEEDS, k=(1.0,)
    )
    config = validate(config)
    name = f"{task}-{algo}-s{CONFIRM_SEEDS}+{SEEDS}-{config.steps}"
    out = results / "runs" / "a2c" / "confirm" / name
    file = common.out_dir(results, "a2c/confirm") / f"{name}.json"
    labels = {"task": task, "algo": algo}
    cache.ensure_replayed(config, out, file, labels, (code, EPISODES))


USER_RUN = "halfcheetah-ldn-s0+10-1000000"
"""The user's command's run directory under `runs/a2c/` (its record under `records/a2c/`)."""


def user_command(results: Path) -> None:
    """Train or reuse `ldn-jax --env halfcheetah --algo ldn --seeds 10`, replay each seed and
    K in gymnasium, and write the IQM per K with the run's wall clock."""
    config = validate(from_preset("paper", env="halfcheetah", algo="ldn", seeds=10))
    out = results / "runs" / "a2c" / USER_RUN
    summary = cache.ensure_run(config, out)
    returns = {k: cache.replay(out, config, EPISODES, k) for k in config.k}
    scores = {k: [float(np.mean(r)) for r in rows] for k, rows in returns.items()}
    every = [s for k in config.k for s in scores[k]]
    data = {
        "command": "ldn-jax --env halfcheetah --algo ldn --seeds 10",
        "commit": cache.code_version(),
        "package_commit": cache.package_commit(),
        "train_seconds": summary["train_seconds"],
        "compile_seconds": summary["compile_seconds"],
        "env_steps_per_second": summary["env_steps_per_second"],
        "imagined_steps": [r.get("imagined_steps") for r in summary["runs"]],
        "gymnasium": {str(k): rows for k, rows in returns.items()},
        "iqm_by_k": {str(k): stats.estimate(scores[k]) for k in config.k},
        "iqm_all": stats.estimate(every),
    }
    folder = common.out_dir(results, "a2c")
    common.write_json(folder / "user-command.json", data)
    user_report(folder)


def user_report(folder: Path) -> None:
    """`user-command.md` from `user-command.json`."""
    data = json.loads((folder / "user-command.json").read_text())
    scores = {k: [float(np.mean(r)) for r in rows] for k, rows in data["gymnasium"].items()}
    lines = [
        f"## The user's command, `{data['command']}`",
        "",
        f"At {data['commit']} (package code of {data['package_commit']}). Greedy return in "
        "gymnasium (10 episodes per seed and K): IQM [95% bootstrap interval]. Exploratory: "
        "seeds 0-4 chose the constants (`experiments/results/a2c/a2c.md`). Training "
        f"{data['train_seconds']:,.0f} s, compile {data['compile_seconds']:,.0f} s, "
        f"{data['env_steps_per_second']:,.0f} env steps/s on the machine that ran it.",
        "",
        "| K | greedy return | per seed |",
        "|---|---|---|",
        *(
            f"| {float(k):g} | {stats.text(data['iqm_by_k'][k])} | "
            + ", ".join(f"{x:,.0f}" for x in row)
            + " |"
            for k, row in scores.items()
        ),
        f"| all {sum(map(len, scores.values()))} | {stats.text(data['iqm_all'])} | |",
    ]
    (folder / "user-command.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {folder}/user-command.json and user-command.md")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", default="halfcheetah")
    parser.add_argument("--arms", default=",".join(ARMS))
    parser.add_argument("--steps", type=int, default=STEPS)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--report", action="store_true", help="train nothing; rebuild the report")
    parser.add_argument("--user-command", action="store_true", help="the user's command only")
    parser.add_argument(
        "--confirm", metavar="ALGO,...", help="the plan's runs on seeds 10-14 of --tasks"
    )
    parser.add_argument("--results", type=Path, default=common.RESULTS)
    args = parser.parse_args(argv)
    if args.user_command:
        common.compile_cache(args.results)
        user_command(args.results)
        return 0
    if args.confirm:
        if unknown := [a for a in args.confirm.split(",") if a not in CONFIRM_ALGOS]:
            parser.error(f"unknown algorithm for --confirm: {', '.join(unknown)}")
        code = cache.code_version()
        common.compile_cache(args.results)
        for task in args.tasks.split(","):
            for algo in args.confirm.split(","):
                confirm(task, algo, args.results, code)
                report(args.results)
        return 0
    tasks, arms = args.tasks.split(","), args.arms.split(",")
    if unknown := [t for t in tasks if t not in TASKS] + [a for a in arms if a not in ARMS]:
        parser.error(f"unknown task or arm: {', '.join(unknown)}")
    if args.report:
        user_report(common.out_dir(args.results, "a2c"))
    else:
        code = cache.code_version()
        common.compile_cache(args.results)
        for task in tasks:
            for arm in arms:
                ensure(task, arm, args, code)
                report(args.results)
    report(args.results)
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
