"""REPORT.md's MuJoCo sections: Tables 4 and 5 and the project's targets at the default
budgets."""

from __future__ import annotations

from experiments.paper.report_format import (
    TITLES,
    Section,
    Table,
    adjusted_text,
    algo_name,
    better,
    budget,
    by_env,
    fmt,
    holm,
    inconclusive,
    iqm,
    mann_whitney,
    mann_whitney_p,
    pm,
    powered_verdict,
    too_wide,
)


def _pending_note(table: dict) -> list[str]:
    pending = [r for r in table["rows"] if r["status"] != "done"]
    if not pending:
        return []
    by_reason: dict[str, list[str]] = {}
    for r in pending:
        names = by_reason.setdefault(r["reason"].removeprefix(f"{r['env']} "), [])
        names += [] if r["env"] in names else [r["env"]]
    return [
        f"Pending at this scale ({reason}): {', '.join(names)}."
        for reason, names in by_reason.items()
    ]


IDLE_SHARE = 0.05
"""A model-based run that imagined fewer steps than this share of its real ones is called
out as what it is: the model-free learner with a model beside it."""


def table4_section(table: dict) -> Section:
    intro = (
        f'Final moving return (our reading of "total moving reward"), {table["seeds"]} seeds '
        "per run, continuous actions (the model predicts standardised state deltas; README). "
        "The paper's values exceed what some tasks can score, so compare the two "
        "algorithms, not the values. On the tasks of a 1M-step budget these are the family "
        'study\'s runs ("The A2C family at the default budgets"): a row that section marks '
        "as trained before its task's default changed is stale here too. Curves: "
        "![table 4](table4/table4.png)"
    )
    header = ["env", "algorithm", "budget", "episodes per seed", "env steps per seed"]
    header += ["final moving return: mean ± s.d.", "IQM [95% CI]", "min", "max"]
    header += ["greedy eval return", "paper"]
    done = [r for r in table["rows"] if r["status"] == "done"]
    rows = [
        [
            r["env"],
            algo_name(r["algo"]),
            budget(r),
            fmt(r.get("episodes_per_seed", r["episodes"]), 0),
            fmt(r["env_steps_per_seed"], 0),
            pm(r["mean"], r["sd"]),
            iqm(r),
            fmt(r["min"]),
            fmt(r["max"]),
            pm(r["eval_return"]["mean"], r["eval_return"]["sd"]),
            fmt(r["paper"]),
        ]
        for r in done
    ]
    findings = table4_findings(done, table.get("plain_a3c", {}))
    title = TITLES["table4"]
    return Section(title, [intro, Table(header, rows), *_pending_note(table)], findings)


def table4_findings(rows: list[dict], plain: dict[str, list[float]] | None = None) -> list[str]:
    """Per task, MBRL-LDN vs A3C-Model on the final moving return: the six tasks are one
    family, so each task's two-sided Mann-Whitney p is Holm-adjusted over the tasks that have
    a test, and the verdict reads the adjusted p: REPRODUCED only where it is below 0.05 and
    MBRL-LDN is higher; A3C-Model higher where it is below 0.05 the other way; otherwise no
    significant difference (inconclusive: the budget below the paper's, or the seeds). Where
    `plain` holds plain A3C's final moving returns on a task (the family study's run of the
    same config), the finding sets MBRL-LDN beside it too."""
    pairs = {
        env: (algos["ldn"], algos["a2c-model"])
        for env, algos in by_env(rows).items()
        if set(algos) >= {"a2c-model", "ldn"}
    }
    raw = {
        env: mann_whitney_p(ldn["final_moving_returns"], model["final_moving_returns"])
        for env, (ldn, model) in pairs.items()
    }
    adjusted = holm(raw)
    family = f"{sum(p is not None for p in raw.values())} tasks"
    findings = []
    for env, (ldn, model) in pairs.items():
        x, y = ldn["final_moving_returns"], model["final_moving_returns"]
        p = adjusted[env]
        short = inconclusive(env, ldn.get("episodes_per_seed"), ldn.get("env_steps_per_seed"))
        if p is None or p >= 0.05:
            verdict = "no significant difference (the paper: MBRL-LDN higher): " + (
                short or too_wide(x, y) or f"inconclusive at {len(x)} seeds"
            )
        elif ldn["mean"] > model["mean"]:
            verdict = "REPRODUCED (MBRL-LDN higher, as in the paper)"
        else:
            verdict = "A3C-Model higher (the paper: MBRL-LDN higher): " + (
                short or "NOT reproduced"
            )
        a3c = ""
        if (plain or {}).get(env):
            a3c_mean = sum(plain[env]) / len(plain[env])
            a3c = (
                f" Plain A3C (the family study's run of the same config) ends at "
                f"{a3c_mean:.1f}: MBRL-LDN against it {mann_whitney(x, plain[env])} "
                f"(descriptive, outside the corrected family), {better(x, plain[env], False)}."
            )
        share = ldn.get("imagined_share")
        idle = (
            f" MBRL-LDN imagined {share:.1%} of its real steps: an A3C run with a model beside it."
            if share is not None and share < IDLE_SHARE
            else ""
        )
        findings.append(
            f"Table 4, {env} ({budget(ldn)}): MBRL-LDN {ldn['mean']:.1f} vs "
            f"A3C-Model {model['mean']:.1f} final moving return "
            f"({adjusted_text(raw[env], p, family)}, {better(x, y, False)}; paper "
            f"{ldn['paper']} vs {model['paper']}): {verdict}.{a3c}{idle}"
        )
    return findings


def table5_section(table: dict) -> Section:
    intro = (
        f"Episodes to reach the top; the paper does not define the top, ours is {table['top']} "
        f"(the dashed line in the figure). {table['seeds']} seeds per run. Curves: "
        "![table 5](table5/table5.png)"
    )
    header = ["env", "algorithm", "the top", "episodes to the top: mean ± s.d.", "IQM [95% CI]"]
    header += ["min", "max", "reached", "final moving return", "IQM [95% CI]"]
    header += ["greedy eval return", "paper"]
    done = [r for r in table["rows"] if r["status"] == "done"]
    rows = [
        [
            r["env"],
            algo_name(r["algo"]),
            f"{r['top']:.0f}",
            pm(r["mean"], r["sd"]),
            iqm(r),
            fmt(r["min"], 0),
            fmt(r["max"], 0),
            f"{r['reached']}/{r['runs']}",
            pm(r["final_moving_return"]["mean"], r["final_moving_return"]["sd"]),
            iqm(r["final_moving_return"]),
            pm(r["eval_return"]["mean"], r["eval_return"]["sd"]),
            fmt(r["paper"]),
        ]
        for r in done
    ]
    algos_by_env = by_env(done)
    raw = {key: p for env, algos in algos_by_env.items() for key, p in table5_p(env, algos).items()}
    adjusted = holm(raw)
    family = f"{sum(p is not None for p in raw.values())} comparisons"
    findings = [
        table5_finding(env, algos, {a: adjusted[e, a] for e, a in adjusted if e == env}, family)
        for env, algos in algos_by_env.items()
    ]
    title = TITLES["table5"]
    return Section(title, [intro, Table(header, rows), *_pending_note(table)], findings)


OTHERS = ("ppo", "ppo-model")
"""What Table 5 tests PPO2-LDN against."""


def to_top_or_budget(row: dict) -> list:
    """Per seed the episodes to the top, every seed counted: a seed that never reached it
    counts at the episodes it took (its budget; the run's mean episodes per seed in files
    from before `episodes_per_run`), so that an unreached seed is never dropped."""
    taken = row.get("episodes_per_run") or [row.get("episodes_per_seed")] * len(
        row["episodes_to_top"]
    )
    return [b if t is None else t for t, b in zip(row["episodes_to_top"], taken, strict=True)]


def _mean(values: list) -> float | None:
    have = [v for v in values if v is not None]
    return sum(have) / len(have) if have else None


def table5_p(env: str, algos: dict[str, dict]) -> dict[tuple[str, str], float | None]:
    """The raw two-sided Mann-Whitney p of PPO2-LDN against each other algorithm of the task
    (`OTHERS`), over every seed (`to_top_or_budget`): `{(env, algo): p}`."""
    if "ppo-ldn" not in algos:
        return {}
    ldn = to_top_or_budget(algos["ppo-ldn"])
    return {(env, a): mann_whitney_p(ldn, to_top_or_budget(algos[a])) for a in OTHERS if a in algos}


def table5_verdict(
    algos: dict[str, dict],
    ldn_fewest: bool,
    short: str | None,
    adjusted: dict[str, float | None] | None = None,
) -> str:
    """REPRODUCED only where PPO2-LDN needs the fewest episodes and Mann-Whitney says so
    against each other algorithm (Holm-adjusted p < 0.05: `adjusted`, per algorithm, over the
    table's comparisons; without it, over this task's); NOT reproduced where another needs
    significantly fewer; otherwise the seeds cannot tell: inconclusive, with the budget where
    it is below the paper's. Every seed counts (`to_top_or_budget`)."""
    ldn = to_top_or_budget(algos["ppo-ldn"]) if "ppo-ldn" in algos else []
    others = {a: to_top_or_budget(r) for a, r in algos.items() if a != "ppo-ldn"}
    if adjusted is None:
        adjusted = holm({a: mann_whitney_p(ldn, top) for a, top in others.items()})
    p = {a: adjusted.get(a) for a in others}
    shown = bool(others) and all(v is not None and v < 0.05 for v in p.values())
    fewer = [
        a
        for a, top in others.items()
        if p[a] is not None and p[a] < 0.05 and _mean(top) < _mean(ldn)
    ]
    reversal = (
        f"{algo_name(fewer[0])} significantly fewer; the paper: PPO2-LDN fewest" if fewer else None
    )
    runs = next(iter(algos.values()))["runs"]
    fewest = "PPO2-LDN fewest"
    return powered_verdict(fewest, fewest, ldn_fewest, shown, reversal, short, runs)


def table5_finding(
    env: str,
    algos: dict[str, dict],
    adjusted: dict[str, float | None] | None = None,
    family: str | None = None,
) -> str:
    """The task's verdict: PPO2-LDN against each other algorithm on every seed (an unreached
    seed at the episodes it took), Holm-adjusted over `family` (`adjusted`: per algorithm;
    without it, over this task's comparisons); and per seed of each model-based run the
    imagined steps and the learner updates made on imagined rows."""
    means = {a: r["mean"] for a, r in algos.items() if r["mean"] is not None}
    if not means:
        some = next(iter(algos.values()))
        short = inconclusive(env, some.get("episodes_per_seed"), some.get("env_steps_per_seed"))
        return f"Table 5, {env}: no run reached the top within the budget" + (
            f": {short}." if short else "."
        )
    order = sorted(means, key=means.get)
    ours = " < ".join(f"{algo_name(a)} ({means[a]:.0f})" for a in order)
    every = {a: to_top_or_budget(r) for a, r in algos.items()}
    every_mean = {a: _mean(v) for a, v in every.items()}
    every_order = sorted((a for a in every_mean if every_mean[a] is not None), key=every_mean.get)
    counted = " < ".join(f"{algo_name(a)} ({every_mean[a]:.0f})" for a in every_order)
    reached = ", ".join(f"{algo_name(a)} {r['reached']}/{r['runs']}" for a, r in algos.items())
    some = next(iter(algos.values()))
    short = inconclusive(env, some.get("episodes_per_seed"), some.get("env_steps_per_seed"))
    raw = {a: p for (_, a), p in table5_p(env, algos).items()}
    if adjusted is None:
        adjusted = holm(raw)
        family = f"{sum(p is not None for p in raw.values())} comparisons"
    ldn_fewest = len(every_order) == len(algos) and every_order[0] == "ppo-ldn"
    verdict = table5_verdict(algos, ldn_fewest, short, adjusted)
    final = {a: r["final_moving_return"]["mean"] for a, r in algos.items()}
    unreached = [a for a, r in algos.items() if r["reached"] == 0]
    unreached = (
        "; never reached the top: "
        + ", ".join(f"{algo_name(a)} (final moving return {final[a]:.0f})" for a in unreached)
        if unreached
        else ""
    )
    tests = "; ".join(
        f"PPO2-LDN vs {algo_name(a)}: "
        + adjusted_text(raw[a], adjusted.get(a), family)
        + ", "
        + better(every["ppo-ldn"], every[a], True)
        for a in OTHERS
        if a in raw
    )
    return (
        f"Table 5, {env}: mean episodes to the top over the seeds that reached it {ours}; over "
        f"every seed, one that never reached it counted at the episodes it took, {counted} "
        f"({tests}). Reached: {reached}{unreached}: {verdict}.{imagined_text(algos)}"
    )


def imagined_text(algos: dict[str, dict]) -> str:
    """Per seed of each model-based run (model-free ones have no LD and no imagined rows):
    the imagined steps and the learner updates made on imagined rows (history metric
    `imagined_updates` summed over the run: PPO learns from its imaginary memory only once
    the memory holds a full batch, so a run may imagine and never learn from it), always
    printed; with a note where a run made none."""
    parts = []
    for a, r in algos.items():
        if r.get("ld_mean_last_iterations") is None and r.get("imagined_updates") is None:
            continue  # model-free
        steps = r.get("imagined_steps") or [None] * len(r.get("imagined_updates") or [])
        updates = r.get("imagined_updates") or [None] * len(steps)
        seeds = ", ".join(f"{fmt(n, 0)}/{fmt(u, 0)}" for n, u in zip(steps, updates, strict=True))
        ld = r.get("ld_mean_last_iterations")
        ld = f", mean LD {ld:.2f}" if ld is not None and a.endswith("ldn") else ""
        mean = f"mean {r.get('imagined_steps_per_seed') or 0:,.0f} steps{ld}"
        parts.append(f"{algo_name(a)} {seeds} ({mean})" if seeds else f"{algo_name(a)} {mean}")
    if not parts:
        return ""
    text = f" Imagined steps / updates on imagined rows, per seed: {'; '.join(parts)}."
    idle = [
        f"{algo_name(a)} made no update on imagined rows in {r['imagined_updates'].count(0)} "
        f"of {len(r['imagined_updates'])} runs"
        + (
            f" (its row repeats {algo_name(a.split('-')[0])}'s)"
            if r["imagined_updates"].count(0) == len(r["imagined_updates"])
            else ""
        )
        for a, r in algos.items()
        if r.get("imagined_updates") and 0 in r["imagined_updates"]
    ]
    return text + (
        f" {'; '.join(idle)}: PPO learns from the imaginary memory only once it holds a full batch."
        if idle
        else ""
    )


def _span(values: list, digits: int = 0) -> str:
    """ "low to high" of the values given, "all N" where they are equal."""
    have = [v for v in values if v is not None]
    if not have:
        return "–"
    if min(have) == max(have):
        return f"{have[0]:,.{digits}f} (all {len(have)})"
    return f"{min(have):,.{digits}f} to {max(have):,.{digits}f}"


def _measured(row: dict, record: dict) -> str:
    """The day a targets row was measured (rows written before rows had dates: the file's)."""
    return row.get("date") or record.get("machine", {}).get("date", "–")


def targets_section(record: dict) -> Section:
    intro = (
        "What the defaults deliver (not a table of the paper): each run at its default budget "
        "(`ldn_jax.presets.TASKS`), as `ldn-jax --env ENV --algo ALGO --seeds N` starts it, "
        "dated by the day each run finished (a row measured under an earlier commit's defaults "
        "is that commit's). Curves"
        + (f" (the runs of {record['curves_date']})" if "curves_date" in record else "")
        + ": ![targets](targets/targets.png)"
    )
    rows = [r for r in record["rows"] if r["status"] == "done"]
    pendulum = [r for r in rows if r["env"] == "inverted_pendulum"]
    cheetah = [r for r in rows if r["env"] == "halfcheetah"]
    parts: list = [intro]
    findings = []
    if pendulum:
        header = ["algorithm", "budget", "seeds >= 900", "env steps to 900", "highest"]
        header += ["final moving return", "greedy eval", "training s", "target met", "measured"]
        parts.append(
            Table(
                header,
                [
                    [
                        r["algo"],
                        r["budget"],
                        f"{r['reached']}/{r['seeds']}",
                        _span(r["steps_to_level"]),
                        _span(r["highest"], 1),
                        _span(r["final_moving_return"]),
                        _span(r["eval_return"]),
                        f"{r['train_seconds']:.0f}",
                        "yes" if r["met"] else "NO",
                        _measured(r, record),
                    ]
                    for r in pendulum
                ],
            )
        )
        met = sum(r["met"] for r in pendulum)
        findings.append(
            f"Targets, inverted_pendulum: {met} of {len(pendulum)} algorithms reach a moving "
            "return of 900 on at least 4 of 5 seeds within the default budget in under 15 "
            "minutes of training ("
            + ", ".join(f"{r['algo']} {r['reached']}/{r['seeds']}" for r in pendulum)
            + ")."
        )
    if cheetah:
        header = ["algorithm", "budget", "runs", "mean moving return: first -> final"]
        header += ["final, per run", "greedy eval, mean", "wall s", "target", "met", "measured"]
        target = {
            "ldn": "rise >= 1,000 in under 30 min",
            "ppo": "mean final >= 2,000",
        }
        table = []
        for r in cheetah:
            runs = len(r["final_moving_return"])
            evals = sum(r["eval_return"]) / runs
            table.append(
                [
                    r["algo"],
                    r["budget"],
                    f"{r['seeds']} seeds x {len(r['k'])} K" if len(r["k"]) > 1 else str(runs),
                    f"{r['first_mean_moving_return']:,.0f} -> {r['final_mean_moving_return']:,.0f}",
                    _span(r["final_moving_return"]),
                    f"{evals:,.0f}",
                    f"{r['wall_seconds']:,.0f}",
                    target.get(r["algo"], ""),
                    "yes" if r["met"] else "NO",
                    _measured(r, record),
                ]
            )
            findings.append(
                f"Targets, halfcheetah {r['algo']}: mean moving return "
                f"{r['first_mean_moving_return']:,.0f} -> {r['final_mean_moving_return']:,.0f} "
                f"over {runs} runs in {r['wall_seconds'] / 60:.0f} minutes "
                f"({target.get(r['algo'], '')}: {'met' if r['met'] else 'NOT met'}; "
                f"measured {_measured(r, record)})."
            )
        parts.append(Table(header, table))
    pending = [r for r in record["rows"] if r["status"] != "done"]
    if pending:
        parts.append(
            "Pending at this scale: " + ", ".join(f"{r['env']} {r['algo']}" for r in pending) + "."
        )
    return Section(TITLES["targets"], parts, findings)
