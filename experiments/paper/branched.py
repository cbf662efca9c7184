"""Stopping rules with branched rollouts (ours; the paper has no such study).

    python -m experiments.paper.branched [--envs ENV,...] [--rules RULE,...] [--seeds N]
        [--steps N] [--results DIR] [--cached]

Under the `branched` preset (short imagined rollouts from real states in a probabilistic
ensemble, `docs/training.md`), every rule that can end a branch, side by side with the PPO
learner alone at the same constants: no rule under fixed caps of 1, 5 and 15 steps, MBPO's
horizon schedule, the LD draw (disagreement and predicted-variance readings) under a cap of
15, M2AC's mask and MACURA's threshold under the same cap; and the cap of 5 with the
policy's log std left to the real updates (`model.imagined_std` "real"), the elites' mean
as each imagined step (`model.imagined_step` "mean"), the real simulator stepped from the
imagined states in the model's place (`model.world` "true": what a perfect model would give;
"true-reward": its reward and termination only; "true-state": its states and termination
only), eight times the model's fit steps, the model fitted to the critic's values too
(`model.value_loss`), imagined rows that train the critic only (`model.imagined_updates`),
twice the imagined steps per real one, or 5 epochs on imagined rows, which are not rules.
Per rule and env: IQM [95% interval] of the final moving return, of the training return over
the last 10% of steps and of the greedy return after training, P(improvement) of the greedy
return over PPO and over the best fixed cap, imagined steps per real step, and training
seconds.

Writes DIR/branched/branched.json, branched.md (REPORT.md's section "Stopping rules with
branched rollouts" is that file) and branched.png (each rule's interval beside PPO's), keeping
the rows of envs and rules not run this time; runs are cached in DIR/runs/branched/ and
resumed; more seeds than a finished run has train only the seeds after its own (10 seeds: an
earlier run of 5, and seeds 5..9).
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

BUDGETS = {"inverted_pendulum": 30_000, "hopper": 200_000, "halfcheetah": 200_000}
"""Real env steps per seed of each env's runs. inverted_pendulum's runs stop once solved
(`SOLVED`), 87 of the study's 100 inside 30k; a longer budget would only move the 13 that
never did (docs/imagination.md)."""

SOLVED = {"inverted_pendulum": 900.0}
"""Envs where every rule ends at a greedy return (`Config.solved_return`): there the study
compares real steps to it, since at the end of the budget every rule has solved the task.
A run that never solves it counts as the budget plus one step."""

SCHEDULES = {
    "inverted_pendulum": {"horizon_from": 2_000, "horizon_to": 20_000},
    "hopper": {"horizon_from": 20_000, "horizon_to": 100_000},
    "halfcheetah": {"horizon_from": 20_000, "horizon_to": 100_000},
}
"""MBPO's schedule (h from 1 to 15) per env: its hopper's step counts, shrunk for the
pendulum's short budget."""

RULES = {
    "ppo": ("ppo", {}, "PPO alone (the same constants)"),
    "cap-5": ("ppo-model", {"horizon": 5}, "no rule, cut at 5 steps"),
    "cap-1": ("ppo-model", {"horizon": 1}, "no rule, cut at 1 step"),
    "cap-15": ("ppo-model", {"horizon": 15}, "no rule, cut at 15 steps"),
    "mbpo": ("ppo-model", {"stop": "mbpo", "horizon": 15}, "MBPO's horizon schedule, 1 to 15"),
    "ld": ("ppo-ldn", {"horizon": 15}, "LD draw, disagreement, cap 15"),
    "ld-variance": ("ppo-ldn", {"ld": "variance", "horizon": 15}, "LD draw, variance, cap 15"),
    "m2ac": ("ppo-model", {"stop": "m2ac", "horizon": 15}, "M2AC mask, cap 15"),
    "macura": ("ppo-model", {"stop": "macura", "horizon": 15}, "MACURA threshold, cap 15"),
    "mean": (
        "ppo-model",
        {"horizon": 5, "imagined_step": "mean"},
        "no rule, cut at 5 steps, the elites' mean step",
    ),
    "std-real": (
        "ppo-model",
        {"horizon": 5, "imagined_std": "real"},
        "no rule, cut at 5 steps, log std from real updates only",
    ),
    "fit-400": (
        "ppo-model",
        {"horizon": 5, "updates": 400},
        "no rule, cut at 5 steps, 8x the model's fit steps (400 per iteration)",
    ),
    "true-5": (
        "ppo-model",
        {"horizon": 5, "world": "true"},
        "the real simulator in the model's place, cut at 5 (a perfect model's bound)",
    ),
    "true-reward-5": (
        "ppo-model",
        {"horizon": 5, "world": "true-reward"},
        "the model's states with the real reward and termination, cut at 5",
    ),
    "value-5": (
        "ppo-model",
        {"horizon": 5, "value_loss": 1.0},
        "no rule, cut at 5 steps, the model also fitted to the critic's values",
    ),
    "true-state-5": (
        "ppo-model",
        {"horizon": 5, "world": "true-state"},
        "the real states and termination with the model's reward, cut at 5",
    ),
    "ratio-8": (
        "ppo-model",
        {"horizon": 5, "imagined_ratio": 8.0},
        "no rule, cut at 5 steps, 8 imagined steps per real one",
    ),
    "ld-ratio-8": (
        "ppo-ldn",
        {"horizon": 15, "imagined_ratio": 8.0},
        "LD draw, disagreement, cap 15, 8 imagined steps per real one",
    ),
    "epochs-5": (
        "ppo-model",
        {"horizon": 5, "imagined_epochs": 5},
        "no rule, cut at 5 steps, 5 epochs on imagined rows",
    ),
    "ld-epochs-10": (
        "ppo-ldn",
        {"horizon": 15, "imagined_epochs": 10},
        "LD draw, disagreement, cap 15, 10 epochs on imagined rows",
    ),
    "critic-5": (
        "ppo-model",
        {"horizon": 5, "imagined_updates": "critic"},
        "no rule, cut at 5 steps, imagined rows train the critic only",
    ),
}
"""Rule -> (algorithm, model fields over the preset's, how the report names it)."""

CAPS = ("cap-1", "cap-5", "cap-15")

ONLY = {
    **{
        rule: ("hopper", "halfcheetah")
        for rule in (
            "std-real",
            "fit-400",
            "value-5",
            "true-5",
            "true-reward-5",
            "true-state-5",
            "critic-5",
        )
    },
    "ratio-8": ("halfcheetah",),
    "ld-ratio-8": ("halfcheetah",),
    "epochs-5": ("halfcheetah",),
    "ld-epochs-10": ("halfcheetah",),
}
"""Rules run on some envs only: inverted_pendulum's PPO has a state-dependent std
(`std-real`), the pendulum is solved by every rule already, and the perfect-model bounds
and variants are questions about the two locomotion tasks."""


def config_of(env: str, rule: str, seeds: int, steps: int, first_seed: int = 0):
    algo, model, _ = RULES[rule]
    if model.get("stop") == "mbpo":
        model = {**model, **SCHEDULES[env]}
    config = from_preset(
        "branched",
        env=env,
        algo=algo,
        seeds=seeds,
        first_seed=first_seed,
        steps=steps,
        model=model,
        solved_return=SOLVED.get(env),
    )
    return validate(config)


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


def _score(row: dict) -> tuple[list, bool]:
    """What a rule is judged on: steps to solve (lower is better) where the env has a
    `SOLVED` return, else the greedy return after training."""
    if row.get("steps_to_solve") is not None:
        return row["steps_to_solve"], True
    return row["eval_return"], False


def _improvement(row: dict, other: dict) -> dict:
    (x, lower), (y, _) = _score(row), _score(other)
    return stats.improvement(x, y, lower_is_better=lower)


def _versus(row: dict, mine: dict, other: str | None) -> str:
    """P(improvement) of `row` over rule `other`, as text."""
    if other is None or other not in mine or other == row["rule"]:
        return "–"
    return stats.improvement_text(_improvement(row, mine[other]))


def section(rows: list[dict]) -> str:
    """The report's markdown section from the study's rows."""
    lines = [
        "## Stopping rules with branched rollouts",
        "",
        "Ours, `python -m experiments.paper.branched`: under the `branched` preset every rule "
        "ends branches of imagination from real states; each env at its budget; IQM [95% "
        "bootstrap interval]. The greedy return is the trainer's own "
        "evaluation after training (10 episodes). P(improvement) compares greedy returns, or, "
        "where every rule solves the task in the budget, real steps to a greedy return of 900 "
        "(a run that never gets there counts as the budget plus one step). Figure: each "
        "rule's IQM and interval beside PPO's, ![branched](branched/branched.png)",
        "",
    ]
    for env in dict.fromkeys(r["env"] for r in rows):
        mine = {r["rule"]: r for r in rows if r["env"] == env}
        caps = [c for c in CAPS if c in mine]
        # The best fixed cap: the highest IQM greedy return, or the fewest steps to solve.
        merit = {}
        for cap in caps:
            scores, lower = _score(mine[cap])
            merit[cap] = (-1.0 if lower else 1.0) * stats.iqm(np.asarray(scores, float))
        best_cap = max(merit, key=merit.get, default=None)
        solving = any(r.get("steps_to_solve") is not None for r in mine.values())
        counts = sorted({len(r["eval_return"]) for r in mine.values()})
        seeds = f"{counts[0]}" if len(counts) == 1 else f"{counts[0]}-{counts[-1]}"
        lines += [
            f"### {env}, {next(iter(mine.values()))['steps']:,} steps, {seeds} seeds",
            "",
            "| rule | seeds | final moving return |"
            + ("" if solving else " training return, last 10% of steps |")
            + " greedy return |"
            + (" real steps to a greedy 900 | solved |" if solving else "")
            + " P(> PPO) | P(> best cap) | imagined per real step | training s |",
            "|---|---|---|---|" + ("---|---|" if solving else "---|") + "---|---|---|---|",
        ]
        for row in mine.values():
            lines.append(
                f"| {RULES[row['rule']][2]} | {len(row['eval_return'])} "
                f"| {stats.text(stats.estimate(row['final_moving_return']))} "
                + ("" if solving else f"| {_late_text(row)} ")
                + f"| {stats.text(stats.estimate(row['eval_return']))} | "
                + (
                    f"{stats.text(stats.estimate(row['steps_to_solve']))} | "
                    f"{sum(s <= row['steps'] for s in row['steps_to_solve'])}/"
                    f"{len(row['steps_to_solve'])} | "
                    if solving
                    else ""
                )
                + f"{_versus(row, mine, 'ppo')} "
                f"| {_versus(row, mine, best_cap)} | {row['imagined_per_real']:.2f} "
                f"| {row['train_seconds']:.0f} |"
            )
        lines.append("")
        verdicts = []
        for rule, row in mine.items():
            if rule == "ppo" or "ppo" not in mine:
                continue
            p = _improvement(row, mine["ppo"])
            low, high = p["ci95"] or (p["probability"], p["probability"])
            verdict = (
                "beats PPO" if low > 0.5 else "worse than PPO" if high < 0.5 else "inconclusive"
            )
            verdicts.append(f"{RULES[row['rule']][2]}: {verdict} (P {p['probability']:.2f})")
        if best_cap:
            verdicts.append(f"best fixed cap: {RULES[best_cap][2]}")
        lines += [f"Verdicts on {env}: " + "; ".join(verdicts) + ".", ""]
        lines += _ld_against(mine, best_cap, env)
        lines += _targets(mine, env)
    return "\n".join(lines)


TARGETS = {
    "halfcheetah": {"final_moving_return": 3000.0, "eval_return": 5000.0},
    "hopper": {"final_moving_return": 2000.0, "eval_return": 2000.0},
}
"""The branched preset's targets at 200k steps (docs/imagination.md): a model-based rule's
IQM, per measure; on both tasks also P(> PPO) above `TARGET_P`."""

TARGET_P = 0.75

MEASURES = {"final_moving_return": "final moving return", "eval_return": "greedy return"}


def _targets(mine: dict, env: str) -> list[str]:
    """Whether the best model-based rule on `env` (the real simulator's bounds left out)
    meets each target, and by how much it misses: one line, or none for an env without
    targets or rows."""
    goals = TARGETS.get(env)
    methods = {
        rule: row
        for rule, row in mine.items()
        if rule != "ppo" and RULES[rule][1].get("world", "model") == "model"
    }
    if goals is None or not methods:
        return []
    parts = []
    for measure, goal in goals.items():
        iqms = {rule: stats.iqm(np.asarray(row[measure], float)) for rule, row in methods.items()}
        best = max(iqms, key=iqms.get)
        value = iqms[best]
        verdict = "met" if value >= goal else f"missed by {goal - value:,.0f}"
        parts.append(
            f"{MEASURES[measure]} >= {goal:,.0f}: {verdict} (the best IQM, {value:,.0f}: "
            f"{RULES[best][2]})"
        )
    if "ppo" in mine:
        chances = {rule: _improvement(row, mine["ppo"]) for rule, row in methods.items()}
        best = max(chances, key=lambda rule: chances[rule]["probability"])
        p = chances[best]["probability"]
        verdict = "met" if p > TARGET_P else f"missed by {TARGET_P - p:.2f}"
        parts.append(
            f"P(> PPO) above {TARGET_P}: {verdict} (the highest, {p:.2f}: {RULES[best][2]})"
        )
    return [
        f"The branched preset's targets on {env}, over the best of its {len(methods)} "
        "model-based rules (a maximum over rules, so an optimistic reading): "
        + "; ".join(parts)
        + ".",
        "",
    ]


def _late_text(row: dict) -> str:
    """The late training return's IQM [95%], or "–" for a row written before it was read."""
    late = [x for x in row.get("late_return") or [] if x is not None]
    return stats.text(stats.estimate(late)) if late else "–"


LD_RIVALS = ("mbpo", "m2ac", "macura")
"""The field's rules the learning degree's draw is set against (the study's question)."""


def _ld_against(mine: dict, best_cap: str | None, env: str) -> list[str]:
    """The study's question on one env: does the LD draw choose branch lengths as well as
    MBPO's schedule, M2AC and MACURA, and as the best fixed cap? P(the LD draw better)."""
    if "ld" not in mine:
        return []
    rivals = [r for r in (*LD_RIVALS, best_cap) if r is not None and r in mine]
    if not rivals:
        return []
    parts = [f"{RULES[r][2]} {_versus(mine['ld'], mine, r)}" for r in rivals]
    return [f"The LD draw against the other rules on {env}, P(better): " + "; ".join(parts), ""]


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


def figure(rows: list[dict], path: Path) -> None:
    """One panel per env: each rule's IQM (dot) and 95% interval (bar) of what it is judged
    on (`_score`), best at the top, PPO's interval shaded behind; rules that put the real
    simulator in the model's place (bounds, not methods) in grey."""
    import matplotlib.pyplot as plt

    envs = list(dict.fromkeys(r["env"] for r in rows))
    if not envs:
        return
    heights = [len([r for r in rows if r["env"] == env]) + 2.5 for env in envs]
    fig, axes = plt.subplots(
        len(envs),
        1,
        figsize=(10, 0.3 * sum(heights)),
        dpi=110,
        squeeze=False,
        gridspec_kw={"height_ratios": heights},
    )
    for ax, env in zip(axes[:, 0], envs, strict=True):
        mine = [r for r in rows if r["env"] == env]
        lower = _score(mine[0])[1]
        marks = []
        for row in mine:
            estimate = stats.estimate(_score(row)[0])
            low, high = estimate["ci95"] or (estimate["iqm"], estimate["iqm"])
            marks.append((estimate["iqm"], low, high, row))
        marks.sort(key=lambda m: m[0], reverse=not lower)
        for y, (iqm, low, high, row) in enumerate(reversed(marks)):
            bound = RULES[row["rule"]][1].get("world", "model") != "model"
            color = "grey" if bound else "black" if row["rule"] == "ppo" else "tab:blue"
            ax.errorbar(iqm, y, xerr=[[iqm - low], [high - iqm]], fmt="o", color=color, capsize=3)
            if row["rule"] == "ppo":
                ax.axvspan(low, high, color="black", alpha=0.08, linewidth=0)
                ax.axvline(iqm, color="black", linewidth=0.8, linestyle="--")
        labels = [f"{RULES[m[3]['rule']][2]} ({len(m[3]['eval_return'])})" for m in reversed(marks)]
        ax.set_yticks(range(len(marks)), labels, fontsize=7)
        ax.set_xlabel(
            "real steps to a greedy 900 (IQM, 95% interval; fewer is better)"
            if lower
            else "greedy return after training (IQM, 95% interval)",
            fontsize=8,
        )
        ax.set_title(f"{env}, {mine[0]['steps']:,} steps (seeds in brackets)", fontsize=9)
        ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


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
    common.write_json(out / "branched.json", {"rows": ordered})
    (out / "branched.md").write_text(section(ordered))
    figure(ordered, out / "branched.png")
    print(f"wrote {out}/branched.json, branched.md and branched.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
