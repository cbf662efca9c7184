"""The `sac` learner's targets under `experiments/plans/sac.md`: inverted_pendulum at 15,000
steps, halfcheetah and hopper at 200,000, seeds 5-9 (confirmatory) and 0-4 (exploratory),
`ldn-jax --algo sac` as the plan ran it (before the warm-up was adopted; the `plan` arm).

    python -m experiments.paper.sac [--tasks TASK,...] [--first-seed S] [--per-run N]
        [--arm plan|warmup] [--report]
    python -m experiments.paper.sac --tasks halfcheetah,hopper --arm warmup --first-seed 15
    python -m experiments.paper.sac --side-by-side [--arm warmup]

Trains every run (a vmapped program of `--per-run` seeds, one by default, so that each seed's
record lands on its own: a 5-seed 200k run takes hours on 2 cores, and a run directory does
not outlive the machine it trained on; resumed when interrupted, reused when finished; the
records under `records/sac/`), then replays each seed's greedy policy in gymnasium (10
episodes, `ldn-jax eval`'s) into `sac/arms/TASK-sac-sS+N-STEPS.json` (committed, with the
commits that trained it); `--report` rebuilds `sac/sac.json` and `sac/sac.md` from them, the
runs of one task, budget, arm and label pooled into one row. The report also reads the
warm-up plan (`experiments/plans/sac-warmup.md`): its selection on the `warmup` arm's seeds 0-4
and, once adopted, its confirmation on that arm's fresh seeds 15-19 (the second command).

`--side-by-side` trains (or reuses) ours where SB3's SAC ran on these cores
(`baselines/sb3_sac.py`, its JSON lines kept in `sac/sb3_sac.jsonl`): halfcheetah, seed 0,
100k steps, one seed as SB3 runs one; `--arm warmup` for today's default, SB3's start. The
report puts the two side by side (greedy return in gymnasium, steps per second, and how
loaded the cores were, from the notes in that file).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from experiments.paper import cache, common, plots
from ldn_jax.config import Config, from_preset, validate
from ldn_jax.host import stats

TASKS = {"inverted_pendulum": (15_000, 1000.0), "halfcheetah": (200_000, 7000.0)}
TASKS["hopper"] = (200_000, 2300.0)
"""Task -> (real steps, the plan's target for the IQM of the greedy returns)."""
SEEDS = 5
PER_RUN = {"inverted_pendulum": 5, "halfcheetah": 1, "hopper": 1}
"""Seeds per vmapped run by default: the pendulum's five train in minutes; a locomotion
seed's 200k steps take most of an hour on 2 cores, and each lands on its own."""
CONFIRMATORY = 5
"""The plan's fresh seeds start here; 0-4 are exploratory."""
FRESH = {"plan": CONFIRMATORY, "warmup": 15}
"""Arm -> the seed its confirmatory runs start from (`experiments/plans/sac.md`,
`experiments/plans/sac-warmup.md`); below it, and on an arm not named, a run is exploratory."""
EPISODES = 10
WARMUP_RULE = ("halfcheetah", 200_000, 0.6)
"""The warm-up plan's selection: task, budget, and the P(improvement) of the `warmup` arm's
seeds 0-4 over the plan's confirmatory seeds that it must exceed (its IQM must exceed theirs)."""
WARMUP_TASKS = ("halfcheetah", "hopper")
"""The warm-up plan's confirmation: `warmup` on its fresh seeds against the plan's, one-sided
Mann-Whitney on each task, Holm over the two."""


ARMS: dict[str, dict[str, object]] = {
    "plan": {"sac.random_steps": 0, "sac.learning_starts": 1000},
    "warmup": {"sac.random_steps": 10_000, "sac.learning_starts": 10_000},
}
"""Arm -> fields over `--algo sac`'s defaults. "plan" is `sac` as the plan ran it: the policy
acts from the first step and updates start at 1,000 rows (the defaults until the warm-up was
adopted, 2026-12-08). "warmup" acts uniformly at random for the first 10,000 steps and
updates from there, as SB3's SAC under the zoo's halfcheetah constants does, and as the
locomotion tasks' defaults now do (`presets.TASKS`)."""

SIDE_BY_SIDE = ("halfcheetah", 0, 1, 100_000)
"""Where ours runs beside SB3's SAC: task, first seed, seeds, steps."""


def config_of(
    task: str, first_seed: int, seeds: int = SEEDS, steps: int | None = None, arm: str = "plan"
) -> Config:
    steps = steps or TASKS[task][0]
    config = from_preset(
        "paper", env=task, algo="sac", seeds=seeds, first_seed=first_seed, steps=steps, **ARMS[arm]
    )
    return validate(config)


def run_dir(
    results: Path, task: str, first_seed: int, seeds: int = SEEDS, steps=None, arm: str = "plan"
) -> Path:
    steps = steps or TASKS[task][0]
    name = "sac" if arm == "plan" else f"sac-{arm}"
    return results / "runs" / "sac" / f"{task}-{name}-s{first_seed}+{seeds}-{steps}"


def ensure(
    task: str, first_seed: int, results: Path, code: str, seeds: int = SEEDS, arm: str = "plan"
) -> None:
    """Train (or resume, or reuse) one run of `seeds` seeds, then replay it in gymnasium."""
    config = config_of(task, first_seed, seeds, arm=arm)
    out = run_dir(results, task, first_seed, seeds, arm=arm)
    file = common.out_dir(results, "sac/arms") / f"{out.name}.json"
    labels = {"task": task} if arm == "plan" else {"task": task, "arm": arm}
    cache.ensure_replayed(config, out, file, labels, (code, EPISODES))


def side_by_side(results: Path, code: str, load: str, arm: str = "plan") -> None:
    """Ours where SB3's SAC ran (`SIDE_BY_SIDE`), into `sac/side/`; `load`: what else ran
    on the cores meanwhile, in words; `arm`: "warmup" for today's default, SB3's start."""
    task, first, seeds, steps = SIDE_BY_SIDE
    config = config_of(task, first, seeds, steps, arm)
    out = run_dir(results, task, first, seeds, steps, arm)
    file = common.out_dir(results, "sac/side") / f"{out.name}.json"
    labels = {"task": task, "load": load} | ({} if arm == "plan" else {"arm": arm})
    cache.ensure_replayed(config, out, file, labels, (code, EPISODES))


def side_lines(results: Path) -> list[str]:
    """The side-by-side table: ours (`sac/side/`) and SB3's (`sac/sb3_sac.jsonl`)."""
    sb3 = results / "sac" / "sb3_sac.jsonl"
    ours = sorted((results / "sac" / "side").glob("*.json"))
    if not sb3.exists() and not ours:
        return []
    lines = [
        "",
        "### Beside SB3's SAC (`baselines/sb3_sac.py`, the zoo's constants)",
        "",
        "One seed each, on these 2 cores; greedy return in gymnasium (ours over 10 "
        "episodes, SB3's over its script's 5). Each "
        "row's load says what else ran on the cores: steps per second are comparable only "
        "between rows that ran under the same load.",
        "",
        "| who | task | seed | steps | greedy return | training s | env steps/s | load | code |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for file in ours:
        data = json.loads(file.read_text())
        if "gymnasium" not in data:
            continue
        mean = float(np.mean(data["gymnasium"][0]))
        who = "ours (`--algo sac`" + (", warm-up" if data.get("arm") == "warmup" else "") + ")"
        lines.append(
            f"| {who} | {data['task']} | {data['seeds'][0]} | {data['steps']:,} | "
            f"{mean:,.0f} | {data['train_seconds']:,.0f} | "
            f"{data['env_steps_per_second']:.0f} | {data.get('load', '–')} | "
            f"{', '.join(data['commits'])} |"
        )
    if sb3.exists():
        for line in sb3.read_text().splitlines():
            r = json.loads(line)
            lines.append(
                f"| SB3 {r.get('sb3', '')} | {r['task']} | {r['seed']} | {r['steps']:,} | "
                f"{r['mean']:,.0f} | {r['train_seconds']:,.0f} | {r['steps_per_second']:.0f} | "
                f"{r.get('load', '–')} | – |"
            )
    return lines


def pooled(results: Path) -> list[dict]:
    """The replayed runs of `sac/arms/`, pooled by task, budget, arm and label (an arm's runs
    from its `FRESH` seed on confirmatory, the rest exploratory), in seed order."""
    groups: dict[tuple, list[dict]] = {}
    for data in cache.replayed(results / "sac" / "arms"):
        arm = data.get("arm", "plan")
        fresh = arm in FRESH and data["seeds"][0] >= FRESH[arm]
        label = "confirmatory" if fresh else "exploratory"
        groups.setdefault((data["task"], data["steps"], arm, label), []).append(data)
    rows = []
    for (task, steps, arm, label), runs in sorted(groups.items()):
        runs.sort(key=lambda r: r["seeds"][0])
        pooled = cache.pool(runs)
        seeds, scores = pooled["seeds"], pooled["scores"]
        target = TASKS[task][1]
        score = stats.estimate(scores)
        rows.append(
            {
                "task": task,
                "steps": steps,
                "arm": arm,
                "label": label,
                "seeds": seeds,
                "scores": scores,
                "score": score,
                "target": target,
                "reached": sum(s >= target for s in scores),
                "complete": len(seeds) >= SEEDS,
                "met": len(seeds) >= SEEDS and score["iqm"] >= target,
                "runs": len(runs),
                "env_steps_per_second": [r["env_steps_per_second"] for r in runs],
                "seeds_per_run": [len(r["seeds"]) for r in runs],
                "commits": pooled["commits"],
            }
        )
    return rows


def _row(rows: list[dict], task: str, steps: int, arm: str, label: str) -> dict | None:
    found = [
        r
        for r in rows
        if (r["task"], r["steps"], r["arm"], r["label"]) == (task, steps, arm, label)
    ]
    return found[0] if found else None


def warmup_decision(rows: list[dict]) -> dict:
    """The warm-up plan's selection rule, read once both sides have their 5 seeds: "adopt"
    where the `warmup` arm's exploratory seeds beat the plan's confirmatory ones on IQM and
    P(improvement) is above the bar, "keep" otherwise, "pending" until then."""
    task, steps, bar = WARMUP_RULE
    warm = _row(rows, task, steps, "warmup", "exploratory")
    plan = _row(rows, task, steps, "plan", "confirmatory")
    if not (warm and plan and warm["complete"] and plan["complete"]):
        return {"verdict": "pending", "task": task, "steps": steps}
    better = stats.improvement(warm["scores"], plan["scores"])
    adopt = warm["score"]["iqm"] > plan["score"]["iqm"] and better["probability"] > bar
    return {
        "verdict": "adopt" if adopt else "keep",
        "task": task,
        "steps": steps,
        "warmup": {"seeds": warm["seeds"], "score": warm["score"]},
        "plan": {"seeds": plan["seeds"], "score": plan["score"]},
        "improvement": better,
        "bar": bar,
    }


def warmup_tests(rows: list[dict]) -> list[dict] | None:
    """The warm-up plan's confirmation: `warmup` on its fresh seeds > the plan's fresh seeds
    at 200k on each of `WARMUP_TASKS`, Holm over them; None until every row is complete."""
    scores = {}
    for task in WARMUP_TASKS:
        for arm in ("warmup", "plan"):
            row = _row(rows, task, TASKS[task][0], arm, "confirmatory")
            if row is None or not row["complete"]:
                return None
            scores[task, arm] = row["scores"]
    return stats.planned_tests(scores, WARMUP_TASKS, [("warmup", "plan")], group="task")


def warmup_lines(decision: dict, tests: list[dict] | None) -> list[str]:
    """`warmup_decision`'s and `warmup_tests`' results as the report's section."""
    lines = ["", "### The warm-up plan (`experiments/plans/sac-warmup.md`)", ""]
    if decision["verdict"] == "pending":
        lines.append(
            f"Selection pending: it reads {decision['task']} at {decision['steps']:,} steps once "
            "the `warmup` arm's seeds 0-4 and the plan's confirmatory seeds are all in."
        )
    else:
        warm, plan = decision["warmup"], decision["plan"]
        lines.append(
            f"Selection ({decision['task']}, {decision['steps']:,} steps): `warmup` seeds "
            f"{_seeds(warm['seeds'])} {stats.text(warm['score'])} against the plan's seeds "
            f"{_seeds(plan['seeds'])} {stats.text(plan['score'])}, P(improvement) "
            f"{stats.improvement_text(decision['improvement'])} (the rule: a higher IQM and "
            f"P above {decision['bar']}): **{decision['verdict']}**."
        )
    lines.append("")
    if tests is None:
        lines.append(
            "Confirmation: waits for the `warmup` arm's seeds "
            f"{FRESH['warmup']}-{FRESH['warmup'] + SEEDS - 1} on "
            f"{' and '.join(WARMUP_TASKS)} (run only if adopted)."
        )
    else:
        lines += ["", *stats.tests_table(tests, "task", "P(improvement)", ("shown", "not shown"))]
    return lines


def runs_of(results: Path, row: dict) -> list[Path]:
    """The run directories behind a `pooled` row, one per run (each reads as its record
    where the directory is gone)."""
    firsts = np.cumsum([0, *row["seeds_per_run"][:-1]])
    return [
        run_dir(results, row["task"], row["seeds"][i], n, row["steps"], row.get("arm", "plan"))
        for i, n in zip(firsts, row["seeds_per_run"], strict=True)
    ]


def _seeds(seeds: list[int]) -> str:
    """5, 6, 7 -> "5-7"; gaps listed."""
    if seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f"{seeds[0]}-{seeds[-1]}" if len(seeds) > 1 else str(seeds[0])
    return ", ".join(map(str, seeds))


def report(results: Path) -> None:
    rows = pooled(results)
    out = common.out_dir(results, "sac")
    decision, tests = warmup_decision(rows), warmup_tests(rows)
    common.write_json(out / "sac.json", {"rows": rows, "warmup": decision, "warmup_tests": tests})
    lines = [
        "## `sac` (plan: `experiments/plans/sac.md`)",
        "",
        "Greedy return in gymnasium per seed (10 episodes); IQM [95% bootstrap interval]. "
        "A row with fewer than the plan's 5 seeds is pending: its target is not read. "
        "Env steps/s: per run (all of its seeds together), one figure per run.",
        "",
        "| task | steps | seeds | arm | label | greedy return | seeds at target | target | met | "
        "env steps/s (seeds per run) | code |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        met = ("yes" if r["met"] else "no") if r["complete"] else "pending"
        speed = ", ".join(
            f"{v:.0f} ({n})"
            for v, n in zip(r["env_steps_per_second"], r["seeds_per_run"], strict=True)
        )
        lines.append(
            f"| {r['task']} | {r['steps']:,} | {_seeds(r['seeds'])} | {r['arm']} | {r['label']} | "
            f"{stats.text(r['score'])} | {r['reached']} of {len(r['scores'])} | "
            f"{r['target']:,.0f} | {met} | {speed} | {', '.join(r['commits'])} |"
        )
    panels: dict[str, dict[str, list[Path]]] = {}
    for r in rows:
        arm = "" if r["arm"] == "plan" else f"{r['arm']}, "
        label = f"{arm}{r['label']}, seeds {_seeds(r['seeds'])}"
        panels.setdefault(r["task"], {})[label] = runs_of(results, r)
    levels = {task: target for task, (_, target) in TASKS.items()}
    title = "sac: training episode returns (trailing mean over 5% of the run)"
    if plots.step_curves(panels, out / "sac.png", title, levels):
        lines += [
            "",
            "Training curves (each seed's episode returns, smoothed): ![sac](sac/sac.png)",
        ]
    lines += warmup_lines(decision, tests)
    lines += side_lines(results)
    (out / "sac.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out}/sac.json and sac.md")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", default=",".join(TASKS))
    parser.add_argument("--first-seed", type=int, default=CONFIRMATORY)
    parser.add_argument(
        "--per-run", type=int, help="seeds per vmapped run (default: PER_RUN's, by task)"
    )
    parser.add_argument("--arm", default="plan", choices=list(ARMS), help="see ARMS")
    parser.add_argument("--report", action="store_true", help="train nothing; rebuild the report")
    parser.add_argument(
        "--side-by-side", action="store_true", help="ours where SB3's SAC ran (halfcheetah, 100k)"
    )
    parser.add_argument("--load", default="–", help="--side-by-side: what else runs meanwhile")
    parser.add_argument("--results", type=Path, default=common.RESULTS)
    args = parser.parse_args(argv)
    tasks = args.tasks.split(",")
    if unknown := [t for t in tasks if t not in TASKS]:
        parser.error(f"unknown task: {', '.join(unknown)}")
    if args.per_run is not None and (args.per_run < 1 or SEEDS % args.per_run):
        parser.error(f"--per-run must divide {SEEDS}")
    if args.side_by_side:
        common.compile_cache(args.results)
        side_by_side(args.results, cache.code_version(), args.load, args.arm)
    elif not args.report:
        code = cache.code_version()
        common.compile_cache(args.results)
        for task in tasks:
            per_run = args.per_run or PER_RUN[task]
            for first in range(args.first_seed, args.first_seed + SEEDS, per_run):
                ensure(task, first, args.results, code, per_run, args.arm)
                report(args.results)
    report(args.results)
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
