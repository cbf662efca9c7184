"""The `sac` learner's targets under `experiments/plans/sac.md`: inverted_pendulum at 15,000
steps, halfcheetah and hopper at 200,000, seeds 5-9 (confirmatory) and 0-4 (exploratory),
`ldn-jax --algo sac` as a user gets it.

    python -m experiments.paper.sac [--tasks TASK,...] [--first-seed S] [--report]
    python -m experiments.paper.sac --side-by-side

Trains every run (one vmapped program of 5 seeds per task; resumed when interrupted, reused
when finished; the records under `records/sac/`), then replays each seed's greedy policy in
gymnasium (10 episodes, `ldn-jax eval`'s) into `sac/arms/TASK-sS.json` (committed, with the
commits that trained it); `--report` rebuilds `sac/sac.json` and `sac/sac.md` from them.

`--side-by-side` trains (or reuses) ours where SB3's SAC ran on these cores
(`baselines/sb3_sac.py`, its JSON lines kept in `sac/sb3_sac.jsonl`): halfcheetah, seed 0,
100k steps, one seed as SB3 runs one; the report puts the two side by side (greedy return in
gymnasium, steps per second, and how loaded the cores were, from the notes in that file).
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


SIDE_BY_SIDE = ("halfcheetah", 0, 1, 100_000)
"""Where ours runs beside SB3's SAC: task, first seed, seeds, steps."""


def config_of(task: str, first_seed: int, seeds: int = SEEDS, steps: int | None = None) -> Config:
    steps = steps or TASKS[task][0]
    return validate(
        from_preset("paper", env=task, algo="sac", seeds=seeds, first_seed=first_seed, steps=steps)
    )


def run_dir(results: Path, task: str, first_seed: int, seeds: int = SEEDS, steps=None) -> Path:
    steps = steps or TASKS[task][0]
    return results / "runs" / "sac" / f"{task}-sac-s{first_seed}+{seeds}-{steps}"


def ensure(task: str, first_seed: int, results: Path, code: str) -> None:
    """Train (or resume, or reuse) one task's run, then replay it in gymnasium."""
    config = config_of(task, first_seed)
    out = run_dir(results, task, first_seed)
    file = common.out_dir(results, "sac/arms") / f"{out.name}.json"
    cache.ensure_replayed(config, out, file, {"task": task}, (code, EPISODES))


def side_by_side(results: Path, code: str, load: str) -> None:
    """Ours where SB3's SAC ran (`SIDE_BY_SIDE`), into `sac/side/`; `load`: what else ran
    on the cores meanwhile, in words."""
    task, first, seeds, steps = SIDE_BY_SIDE
    config = config_of(task, first, seeds, steps)
    out = run_dir(results, task, first, seeds, steps)
    file = common.out_dir(results, "sac/side") / f"{out.name}.json"
    cache.ensure_replayed(config, out, file, {"task": task, "load": load}, (code, EPISODES))


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
        lines.append(
            f"| ours (`--algo sac`) | {data['task']} | {data['seeds'][0]} | {data['steps']:,} | "
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
    lines += side_lines(results)
    (out / "sac.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out}/sac.json and sac.md")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", default=",".join(TASKS))
    parser.add_argument("--first-seed", type=int, default=CONFIRMATORY)
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
    if args.side_by_side:
        common.compile_cache(args.results)
        side_by_side(args.results, cache.code_version(), args.load)
    elif not args.report:
        code = cache.code_version()
        common.compile_cache(args.results)
        for task in tasks:
            ensure(task, args.first_seed, args.results, code)
            report(args.results)
    report(args.results)
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
