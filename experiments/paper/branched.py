"""Stopping rules with branched rollouts (ours; the paper has no such study).

    python -m experiments.paper.branched [--envs ENV,...] [--rules RULE,...] [--seeds N]
        [--steps N] [--results DIR] [--cached]

Under the `branched` preset (short imagined rollouts from real states in a probabilistic
ensemble, `docs/training.md`), every rule that can end a branch, side by side with the PPO
learner alone at the same constants: no rule under fixed caps of 1, 5 and 15 steps, MBPO's
horizon schedule, the LD draw (disagreement and predicted-variance readings) under a cap of
15, M2AC's mask and MACURA's threshold under the same cap; and the cap of 5 with the
policy's log std left to the real updates (`imagine.std` "real"), the elites' mean
as each imagined step (`model.imagined_step` "mean"), the real simulator stepped from the
imagined states in the model's place (`model.world` "true": what a perfect model would give;
"true-reward": its reward and termination only; "true-state": its states and termination
only), eight times the model's fit steps, the model fitted to the critic's values too
(`fit.value_loss`), imagined rows that train the critic only (`imagine.updates`),
branches from the newest real states only (`imagine.start_window`),
twice the imagined steps per real one, or 5 epochs on imagined rows, which are not rules.
Per rule and env: IQM [95% interval] of the final moving return, of the training return over
the last 10% of steps and of the greedy return after training, P(improvement) of the greedy
return over PPO and over the best fixed cap, imagined steps per real step, and training
seconds.

Writes DIR/branched/branched.json, branched.md (REPORT.md's section "Stopping rules with
branched rollouts" is that file) and branched.png (each rule's interval beside PPO's), keeping
the rows of envs and rules not run this time; runs are cached in DIR/runs/branched/ and
resumed; more seeds than a finished run has train only the seeds after its own (10 seeds: an
earlier run of 5, and seeds 5..9). The rules and budgets are `branched_rules`'s; the
section and figure, `report_branched`'s.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from experiments.paper import cache, common
from experiments.paper.branched_rules import BUDGETS, ONLY, RULES, SOLVED, config_of
from experiments.paper.report_branched import figure, section
from ldn_jax.host.run_dir import RunDir


def run_dirs(runs: Path, env: str, rule: str, seeds: int, steps: int) -> list[tuple]:
    """`(first seed, seeds, directory)` of the runs that make up `seeds` seeds of a rule: a
    run of them all if one was started; else the finished run of the most seeds below
    `seeds` in `runs`, if any, and the finished runs of the seeds after it (`s5+5`, then
    `s10+5`, ...) as far as they go below `seeds`, then one of the seeds left
    (`first_seed`): 10 seeds reuse an earlier run of 5, 15 seeds those of 5 and 5 more."""
    whole = runs / f"{env}-{rule}-s{seeds}-{steps}"
    if RunDir(whole).holds_run():
        return [(0, seeds, whole)]

    def finished(pattern: str) -> list[tuple[int, Path]]:
        """(seeds, directory) of the finished runs `{env}-{rule}-s{pattern}{N}-{steps}`."""
        found = []
        name = f"{env}-{rule}-s{pattern}*-{steps}"
        paths = {*runs.glob(name)}
        if (records := cache.record_of(runs)) is not None:  # runs whose directory is gone
            paths |= {runs / record.name for record in records.glob(name)}
        for path in sorted(paths):
            count = path.name.removeprefix(f"{env}-{rule}-s{pattern}").removesuffix(f"-{steps}")
            if count.isdigit() and cache.has_finished(path):
                found.append((int(count), path))
        return found

    parts, done = [], 0
    first = [(n, path) for n, path in finished("") if n < seeds]
    if first:
        done, path = max(first)
        parts.append((0, done, path))
        while more := [(n, path) for n, path in finished(f"{done}+") if done + n < seeds]:
            n, path = max(more)
            parts.append((done, n, path))
            done += n
    rest = f"s{seeds}" if not done else f"s{done}+{seeds - done}"
    return [*parts, (done, seeds - done, runs / f"{env}-{rule}-{rest}-{steps}")]


def merged(parts: list[dict]) -> dict:
    """One row from rows of the same rule on consecutive seeds (its training seconds: the
    parts' sum, each part one program)."""
    row = dict(parts[0])
    for name in ("final_moving_return", "eval_return", "steps_to_solve", "late_return"):
        lists = [part.get(name) for part in parts]
        row[name] = None if None in lists else [x for values in lists for x in values]
    row["seeds"] = sum(part["seeds"] for part in parts)
    imagined = sum(part["imagined_per_real"] * part["seeds"] for part in parts)
    row["imagined_per_real"] = imagined / row["seeds"]
    row["train_seconds"] = sum(part["train_seconds"] for part in parts)
    return row


def results_of(env: str, rule: str, out: Path, summary: dict, steps: int) -> dict:
    runs = summary["runs"]
    history = cache.load_history(out)
    real = history["env_steps"][0, :, -1]
    imagined = history["imagined_steps"][0, :, -1]
    return {
        "env": env,
        "rule": rule,
        "steps": steps,
        "seeds": len(runs),
        "name": RULES[rule][2],
        "final_moving_return": [r["final_moving_return"] for r in runs],
        "eval_return": [r["eval_return"] for r in runs],
        "imagined_per_real": float(np.mean(imagined / np.maximum(real, 1))),
        "steps_to_solve": [r["solved"]["env_steps"] if r.get("solved") else steps + 1 for r in runs]
        if env in SOLVED
        else None,
        "late_return": None if env in SOLVED else late_returns(history, steps),
        "train_seconds": summary["train_seconds"],
    }


LATE = 0.9
"""The late training return reads the iterations after this share of the budget."""


def late_returns(history: dict, steps: int) -> list[float | None]:
    """Each seed's mean return over its training episodes that ended after `LATE` of the
    budget (K = 1; None where none did): where the stochastic policy stands at the end. The
    moving return (decay 0.99, about the last 100 episodes) averages far back on a task of
    1,000-step episodes: 200 episodes per seed in 200k steps. Under schedule "episodes"
    (no per-episode step counts) an iteration's episodes count where the iteration ends
    after it."""
    if history["env_steps"].shape[0] != 1:
        raise ValueError("the late return reads runs of one K")
    returns = history["returns"][0]
    if "ended" in history:
        late = history["ended"][0] & (history["steps_at"][0] > LATE * steps)
    else:
        late = np.broadcast_to((history["env_steps"][0] > LATE * steps)[..., None], returns.shape)
    return [float(r[m].mean()) if m.any() else None for r, m in zip(returns, late, strict=True)]


def recorded(runs: Path, row: dict) -> bool:
    """Whether every run a row is made of has a committed record (`cache.record_of`)."""
    dirs = run_dirs(runs, row["env"], row["rule"], len(row["eval_return"]), row["steps"])
    records = [cache.record_of(run) for _, _, run in dirs]
    return all(r is not None and RunDir(r).summary_file.is_file() for r in records)


def _earlier(path: Path) -> list[dict]:
    """The rows an earlier call wrote (rows of rules or envs no longer studied dropped)."""
    if not path.exists():
        return []
    rows = json.loads(path.read_text())["rows"]
    return [r for r in rows if r["env"] in BUDGETS and r["rule"] in RULES]


def _same_row(row: dict | None, other: dict) -> bool:
    return row is not None and all(
        row[name] == other[name] for name in ("eval_return", "train_seconds")
    )


def _cached(out: Path, runs: Path, args: argparse.Namespace) -> dict:
    """`--cached`: `{(env, rule): (row, written row)}`, the written rows of `args.envs` and
    `args.rules` re-read from their runs (at each row's seeds and steps, the runs
    `run_dirs` names for them now) where every part is finished; no training."""
    rows = {}
    envs, rules = args.envs.split(","), args.rules.split(",")
    for row in _earlier(out / "branched.json"):
        env, rule, steps = row["env"], row["rule"], row["steps"]
        if env not in envs or rule not in rules:
            continue
        dirs = run_dirs(runs, env, rule, len(row["eval_return"]), steps)
        summaries = [cache.finished_summary(run) for _, _, run in dirs]
        if None not in summaries:
            parts = [
                results_of(env, rule, run, summary, steps)
                for (_, _, run), summary in zip(dirs, summaries, strict=True)
            ]
            rows[env, rule] = merged(parts), row
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", default=",".join(BUDGETS))
    parser.add_argument("--rules", default=",".join(RULES))
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--steps", type=int, default=None, help="every env's budget instead")
    parser.add_argument("--results", type=Path, default=common.RESULTS)
    parser.add_argument(
        "--cached",
        action="store_true",
        help="train nothing: re-read each written row of ENVS and RULES from its runs, at the "
        "row's own seeds, where they are all finished (rows of runs no longer on disk stay)",
    )
    args = parser.parse_args(argv)
    unknown = [n for n in args.envs.split(",") if n not in BUDGETS]
    unknown += [n for n in args.rules.split(",") if n not in RULES]
    if unknown:
        parser.error(f"unknown env or rule: {', '.join(unknown)}")
    out = common.out_dir(args.results, "branched")
    runs = args.results / "runs" / "branched"
    refreshed = _cached(out, runs, args) if args.cached else {}
    mine = {}
    for env in [] if args.cached else args.envs.split(","):
        steps = args.steps or BUDGETS[env]
        for rule in args.rules.split(","):
            if env not in ONLY.get(rule, (env,)):
                continue
            parts = []
            for first, seeds, run in run_dirs(runs, env, rule, args.seeds, steps):
                summary = cache.ensure_run(config_of(env, rule, seeds, steps, first), run)
                parts.append(results_of(env, rule, run, summary, steps))
            mine[env, rule] = merged(parts)
    # Read only now, so that rows another call wrote while these trained stay.
    rows = {(r["env"], r["rule"]): r for r in _earlier(out / "branched.json")} | mine
    for key, (row, started) in refreshed.items():  # unless another call rewrote it meanwhile
        if _same_row(rows.get(key), started):
            rows[key] = row
    envs, rules = list(BUDGETS), list(RULES)
    ordered = [
        rows[key] for key in sorted(rows, key=lambda k: (envs.index(k[0]), rules.index(k[1])))
    ]
    for row in ordered:
        row["recorded"] = recorded(runs, row)
    common.write_json(out / "branched.json", {"rows": ordered})
    (out / "branched.md").write_text(section(ordered))
    figure(ordered, out / "branched.png")
    print(f"wrote {out}/branched.json, branched.md and branched.png")
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
