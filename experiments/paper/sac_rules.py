"""Which rule should set MBPO's rollout length, under `experiments/plans/sac-rules.md`: `sac`,
`sac-model` (MBPO's schedule) and `sac-ldn` (the LD draw) on hopper and halfcheetah at 100k
real steps, UTD 1, seeds 10-14, one seed per run.

    python -m experiments.paper.sac_rules [--tasks TASK,...] [--arms ARM,...]
        [--seeds SEED,...] [--report]

Trains every run (resumed when interrupted, reused when finished; a finished run leaves its
record under `records/sac-rules/`), replays each seed's greedy policy in gymnasium (10
episodes) into `sac-rules/arms/TASK-ARM-sS.json` (committed, with the commits that trained it
and the steps it imagined), and rebuilds `sac-rules/sac-rules.json` and `.md`: each arm's IQM,
and the plan's six one-sided Mann-Whitney tests with Holm's correction once every seed of
both tasks is in. `--seeds` picks some of the plan's seeds, so that two processes can train
two at once.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from experiments.paper import cache, common, plots
from ldn_jax.config import Config, from_preset, validate
from ldn_jax.host import stats

TASKS = ("hopper", "halfcheetah")
ARMS = ("sac", "sac-model", "sac-ldn")
COMPARISONS = (("sac-ldn", "sac-model"), ("sac-ldn", "sac"), ("sac-model", "sac"))
STEPS = 100_000
FIRST_SEED, SEEDS = 10, 5
EPISODES = 10
ALPHA = 0.05


def config_of(task: str, arm: str, seed: int, steps: int = STEPS) -> Config:
    return validate(
        from_preset("branched", env=task, algo=arm, seeds=1, first_seed=seed, steps=steps)
    )


def run_dir(results: Path, task: str, arm: str, seed: int, steps: int = STEPS) -> Path:
    return results / "runs" / "sac-rules" / f"{task}-{arm}-s{seed}+1-{steps}"


def ensure(task: str, arm: str, seed: int, results: Path, code: str) -> None:
    """Train (or resume, or reuse) one seed's run, then replay it in gymnasium."""
    out = run_dir(results, task, arm, seed)
    file = common.out_dir(results, "sac-rules/arms") / f"{task}-{arm}-s{seed}.json"
    config, labels = config_of(task, arm, seed), {"task": task, "arm": arm}
    cache.ensure_replayed(config, out, file, labels, (code, EPISODES), cache.imagined)


def rows_of(results: Path) -> list[dict]:
    """Per task and arm: the replayed seeds of the plan, their greedy returns and IQM."""
    found: dict[tuple[str, str], list[dict]] = {}
    for data in cache.replayed(results / "sac-rules" / "arms"):
        if data["steps"] == STEPS:
            found.setdefault((data["task"], data["arm"]), []).append(data)
    rows = []
    for task in TASKS:
        for arm in ARMS:
            runs = sorted(found.get((task, arm), []), key=lambda r: r["seeds"][0])
            if not runs:
                continue
            pooled = cache.pool(runs)
            imagined = sum(r.get("imagined_steps", 0) for r in runs)
            real = sum(r.get("env_steps", 0) for r in runs)
            rows.append(
                {
                    "task": task,
                    "arm": arm,
                    "seeds": pooled["seeds"],
                    "scores": pooled["scores"],
                    "score": stats.estimate(pooled["scores"]),
                    "imagined_per_real": imagined / real if real else None,
                    "train_seconds": [r["train_seconds"] for r in runs],
                    "commits": pooled["commits"],
                }
            )
    return rows


def tests(rows: list[dict]) -> list[dict] | None:
    """The plan's six comparisons with Holm's correction; None until every arm of both tasks
    has all its seeds."""
    scores = {(r["task"], r["arm"]): r["scores"] for r in rows if len(r["seeds"]) == SEEDS}
    return stats.planned_tests(scores, TASKS, COMPARISONS, ALPHA, group="task")


def section(rows: list[dict], found: list[dict] | None) -> str:
    lines = [
        "## Which rule sets MBPO's rollout length (plan: `experiments/plans/sac-rules.md`)",
        "",
        f"`--preset branched`, UTD 1, {STEPS:,} real steps, seeds {FIRST_SEED}-"
        f"{FIRST_SEED + SEEDS - 1} (confirmatory), one seed per run. Greedy return in "
        "gymnasium (10 episodes per seed); IQM [95% bootstrap interval].",
        "",
        "| task | arm | seeds | greedy return | imagined per real step | hours per seed | code |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        hours = sum(r["train_seconds"]) / len(r["train_seconds"]) / 3600
        ratio = "–" if r["imagined_per_real"] is None else f"{r['imagined_per_real']:.1f}"
        lines.append(
            f"| {r['task']} | `{r['arm']}` | {len(r['seeds'])} of {SEEDS} | "
            f"{stats.text(r['score'])} | {ratio} | {hours:.2f} | {', '.join(r['commits'])} |"
        )
    lines.append("")
    if found is None:
        lines.append("The tests wait for every seed of every arm on both tasks.")
        return "\n".join(lines) + "\n"
    lines += [
        "One-sided Mann-Whitney U, 5 against 5; Holm over the six tests.",
        "",
    ]
    lines += stats.tests_table(found, "task", "P(improvement)", ("shown", "not shown at 5 seeds"))
    return "\n".join(lines) + "\n"


def report(results: Path) -> None:
    rows = rows_of(results)
    found = tests(rows)
    out = common.out_dir(results, "sac-rules")
    common.write_json(out / "sac-rules.json", {"rows": rows, "tests": found})
    panels: dict[str, dict[str, list[Path]]] = {}
    for r in rows:
        runs = [run_dir(results, r["task"], r["arm"], seed) for seed in r["seeds"]]
        panels.setdefault(r["task"], {})[r["arm"]] = runs
    title = "training episode returns per arm, UTD 1 (trailing mean)"
    text = section(rows, found)
    if plots.step_curves(panels, out / "sac-rules.png", title):
        text += "\nTraining curves per arm: ![sac-rules](sac-rules/sac-rules.png)\n"
    (out / "sac-rules.md").write_text(text)
    print(f"wrote {out}/sac-rules.json and sac-rules.md")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", default=",".join(TASKS))
    parser.add_argument("--arms", default=",".join(ARMS))
    plan = range(FIRST_SEED, FIRST_SEED + SEEDS)
    parser.add_argument("--seeds", default=",".join(map(str, plan)), help="the plan's: 10-14")
    parser.add_argument("--report", action="store_true", help="train nothing; rebuild the report")
    parser.add_argument("--results", type=Path, default=common.RESULTS)
    args = parser.parse_args(argv)
    tasks, arms = args.tasks.split(","), args.arms.split(",")
    if unknown := [t for t in tasks if t not in TASKS] + [a for a in arms if a not in ARMS]:
        parser.error(f"unknown task or arm: {', '.join(unknown)}")
    try:
        seeds = [int(s) for s in args.seeds.split(",")]
    except ValueError:
        parser.error(f"--seeds takes seeds of the plan ({plan[0]}-{plan[-1]}), got {args.seeds}")
    if outside := [s for s in seeds if s not in plan]:
        parser.error(f"--seeds: not a seed of the plan ({plan[0]}-{plan[-1]}): {outside}")
    if not args.report:
        code = cache.code_version()
        common.compile_cache(args.results)
        for task in tasks:
            for seed in seeds:
                for arm in arms:
                    ensure(task, arm, seed, args.results, code)
                    report(args.results)
    report(args.results)
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
