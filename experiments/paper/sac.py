"""The `sac` learner's targets under `experiments/plans/sac.md`: inverted_pendulum at 15,000
steps, halfcheetah and hopper at 200,000, seeds 5-9 (confirmatory) and 0-4 (exploratory),
`ldn-jax --algo sac` as a user gets it.

    python -m experiments.paper.sac [--tasks TASK,...] [--first-seed S] [--report]

Trains every run (one vmapped program of 5 seeds per task; resumed when interrupted, reused
when finished; the records under `records/sac/`), then replays each seed's greedy policy in
gymnasium (10 episodes, `ldn-jax eval`'s) into `sac/arms/TASK-sS.json` (committed, with the
commits that trained it); `--report` rebuilds `sac/sac.json` and `sac/sac.md` from them.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from experiments.paper import cache, common
from ldn_jax.config import Config, from_preset, validate
from ldn_jax.host import stats

TASKS = {"inverted_pendulum": (15_000, 1000.0), "halfcheetah": (200_000, 7000.0)}
TASKS["hopper"] = (200_000, 2300.0)
"""Task -> (real steps, the plan's target for the IQM of the greedy returns)."""
SEEDS = 5
CONFIRMATORY = 5
"""The plan's fresh seeds start here; 0-4 are exploratory."""
EPISODES = 10


def config_of(task: str, first_seed: int) -> Config:
    steps = TASKS[task][0]
    return validate(
        from_preset("paper", env=task, algo="sac", seeds=SEEDS, first_seed=first_seed, steps=steps)
    )


def run_dir(results: Path, task: str, first_seed: int) -> Path:
    return results / "runs" / "sac" / f"{task}-sac-s{first_seed}+{SEEDS}-{TASKS[task][0]}"


def ensure(task: str, first_seed: int, results: Path, code: str) -> None:
    """Train (or resume, or reuse) one task's run, then replay it in gymnasium."""
    config = config_of(task, first_seed)
    out = run_dir(results, task, first_seed)
    file = common.out_dir(results, "sac/arms") / f"{out.name}.json"
    cache.ensure_replayed(config, out, file, {"task": task}, (code, EPISODES))


def report(results: Path) -> None:
    rows = []
    for file in sorted((results / "sac" / "arms").glob("*.json")):
        data = json.loads(file.read_text())
        if "gymnasium" not in data:
            continue
        scores = [float(np.mean(r)) for r in data["gymnasium"]]
        target = TASKS[data["task"]][1]
        score = stats.estimate(scores)
        confirmatory = data["seeds"][0] >= CONFIRMATORY
        rows.append(
            {
                **{k: v for k, v in data.items() if k != "gymnasium"},
                "scores": scores,
                "score": score,
                "target": target,
                "reached": sum(s >= target for s in scores),
                "met": score["iqm"] >= target,
                "label": "confirmatory" if confirmatory else "exploratory",
            }
        )
    out = common.out_dir(results, "sac")
    common.write_json(out / "sac.json", {"rows": rows})
    lines = [
        "## `sac` (plan: `experiments/plans/sac.md`)",
        "",
        "Greedy return in gymnasium per seed (10 episodes); IQM [95% bootstrap interval].",
        "",
        "| task | steps | seeds | label | greedy return | seeds at target | target | met | "
        "env steps/s (all seeds) | code |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        seeds = f"{r['seeds'][0]}-{r['seeds'][-1]}"
        lines.append(
            f"| {r['task']} | {r['steps']:,} | {seeds} | {r['label']} | {stats.text(r['score'])} "
            f"| {r['reached']} of {len(r['scores'])} | {r['target']:,.0f} | "
            f"{'yes' if r['met'] else 'no'} | {r['env_steps_per_second']:.0f} | "
            f"{', '.join(r['commits'])} |"
        )
    (out / "sac.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out}/sac.json and sac.md")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", default=",".join(TASKS))
    parser.add_argument("--first-seed", type=int, default=CONFIRMATORY)
    parser.add_argument("--report", action="store_true", help="train nothing; rebuild the report")
    parser.add_argument("--results", type=Path, default=common.RESULTS)
    args = parser.parse_args(argv)
    tasks = args.tasks.split(",")
    if unknown := [t for t in tasks if t not in TASKS]:
        parser.error(f"unknown task: {', '.join(unknown)}")
    if not args.report:
        code = cache.code_version()
        common.compile_cache(args.results)
        for task in tasks:
            ensure(task, args.first_seed, args.results, code)
            report(args.results)
    report(args.results)
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
