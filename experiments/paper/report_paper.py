"""REPORT.md's sections on the paper's CartPole results: Tables 2 and 3 and Figures 4, 5
and 9 (whose MuJoCo panels are here too), each built from its result file."""

from __future__ import annotations

from pathlib import Path

from experiments.paper import common
from experiments.paper.report_format import (
    TITLES,
    Bullets,
    Section,
    Table,
    algo_name,
    better,
    budget,
    by_env,
    fmt,
    holm,
    inconclusive,
    iqm,
    mann_whitney_p,
    pm,
    powered_verdict,
)


def _pending(r: dict, columns: int) -> list[str]:
    """A table row for a run not done: env, algorithm, "pending", the rest empty."""
    return [r["env"], algo_name(r["algo"]), "pending", *[""] * (columns - 3)]


def table2_section(table: dict) -> Section:
    rows = []
    header = ["env", "algorithm", "ours: mean ± s.d.", "IQM [95% CI]", "min", "max", "reached"]
    header.append("paper: mean ± s.d.")
    for r in table["rows"]:
        if r["status"] != "done":
            rows.append(_pending(r, len(header)))
            continue
        rows.append(
            [
                r["env"],
                algo_name(r["algo"]),
                pm(r["mean"], r["sd"]),
                iqm(r),
                fmt(r["min"], 0),
                fmt(r["max"], 0),
                f"{r['reached']}/{r['runs']}",
                pm(r["paper_mean"], r["paper_sd"]),
            ]
        )
    intro = (
        "Moving return m <- 0.99 m + 0.01 R reaching 150 (v0, v1) or 100 (v2). Ours: "
        f"{table['seeds']} seeds, budget {table['episodes']:,} episodes. Box plot (the paper's "
        "Figure 6): `table2/figure6.png`."
    )
    title = TITLES["table2"]
    return Section(title, [intro, Table(header, rows)], table2_findings(table["rows"]))


PAPER_ORDER = ("ldn", "a2c-model", "a2c")
"""The paper's Table 2 ordering, fewest episodes first."""


def compare(a: dict, b: dict) -> str:
    """`a` vs `b` (rows with per-seed episodes): the difference of means, a two-sided
    Mann-Whitney p and the probability that a seed of `a` takes fewer episodes than one of
    `b`, over the seeds that reached the threshold."""
    p = mann_whitney_p(a["episodes_to_threshold"], b["episodes_to_threshold"])
    if p is None:
        return f"{algo_name(a['algo'])} vs {algo_name(b['algo'])}: too few runs reached"
    paper = a["paper_mean"] < b["paper_mean"]
    ours = a["mean"] < b["mean"]
    agree = "as in the paper" if ours == paper else "unlike the paper"
    improvement = better(a["episodes_to_threshold"], b["episodes_to_threshold"], True)
    return (
        f"{algo_name(a['algo'])} {a['mean'] - b['mean']:+.0f} episodes vs "
        f"{algo_name(b['algo'])} (Mann-Whitney p = {p:.2g}, {improvement}; {agree})"
    )


def table2_findings(rows: list[dict]) -> list[str]:
    findings = []
    for env, algos in by_env(rows).items():
        means = {a: r["mean"] for a, r in algos.items() if r["mean"] is not None}
        reached = ", ".join(f"{algo_name(a)} {r['reached']}/{r['runs']}" for a, r in algos.items())
        order = sorted(means, key=means.get)
        ours = " < ".join(f"{algo_name(a)} ({means[a]:.0f})" for a in order)
        if order == [a for a in PAPER_ORDER if a in means] and len(means) == len(algos):
            verdict = "REPRODUCED (the paper's ordering MBRL-LDN < A3C-Model < A3C)"
        elif order and order[0] == "ldn":
            verdict = "PARTLY reproduced (MBRL-LDN fewest, the rest in another order)"
        else:
            verdict = "NOT reproduced (the paper: MBRL-LDN < A3C-Model < A3C)"
        pairs = [
            compare(algos[a], algos[b])
            for a, b in (("ldn", "a2c"), ("ldn", "a2c-model"), ("a2c-model", "a2c"))
            if a in algos and b in algos and a in means and b in means
        ]
        ratio = [
            means[a] / r["paper_mean"]
            for a, r in algos.items()
            if a in means and r["paper_mean"] is not None
        ]
        scale = (
            f" In absolute terms ours take {min(ratio):.1f}-{max(ratio):.1f}x the paper's episodes."
            if ratio
            else ""
        )
        findings.append(
            f"Table 2, {env}: mean episodes {ours or 'none reached'}: {verdict}. "
            + ("; ".join(pairs) + ". " if pairs else "")
            + f"Reached: {reached}.{scale}"
        )
    return findings


def table3_section(table: dict) -> Section:
    seeds = table["seeds"]
    intro = (
        f"From the Table 2 runs. *Batch seconds*: training wall time of the run ({seeds} seeds "
        "in one vmapped program) when a seed crossed, compilation excluded (given apart). "
        f"*Per seed*: batch seconds / {seeds}, what one seed costs if vmapping were free "
        "(a lower bound, not a measurement). The paper ran one agent with 8 asynchronous "
        "workers on its own machine; compare ratios between algorithms, not absolute values. "
        "Figure: `table3/table3.png`."
    )
    header = ["env", "algorithm", "batch seconds: mean ± s.d.", "per seed", "compile s"]
    header += ["real env steps to threshold", "paper seconds"]
    rows = []
    for r in table["rows"]:
        if r["status"] != "done":
            rows.append(_pending(r, len(header)))
            continue
        rows.append(
            [
                r["env"],
                algo_name(r["algo"]),
                pm(r["mean"], r["sd"]),
                pm(r["per_seed_mean"], r["per_seed_sd"], 2),
                fmt(r["compile_seconds"]),
                fmt(r["env_steps_mean"], 0),
                fmt(r["paper_seconds"]),
            ]
        )
    findings = []
    for env, algos in by_env(table["rows"]).items():
        if "a2c" not in algos or algos["a2c"]["mean"] is None:
            continue
        base = algos["a2c"]["mean"]
        parts, paper_parts = [], []
        for algo in ("a2c-model", "ldn"):
            if algo in algos and algos[algo]["mean"] is not None:
                parts.append(f"{algo_name(algo)} {algos[algo]['mean'] / base:.2f}x")
            paper = common.PAPER_TABLE3.get((algo, env))
            paper_base = common.PAPER_TABLE3.get(("a2c", env))
            if paper and paper_base:
                paper_parts.append(f"{algo_name(algo)} {paper / paper_base:.2f}x")
        fastest = min(
            (a for a in algos if algos[a]["mean"] is not None), key=lambda a: algos[a]["mean"]
        )
        verdict = (
            "REPRODUCED (A3C fastest in seconds, as in the paper)"
            if fastest == "a2c"
            else f"NOT reproduced ({algo_name(fastest)} fastest; in the paper A3C is)"
        )
        findings.append(
            f"Table 3, {env}: seconds relative to A3C: ours {', '.join(parts)}; paper "
            f"{', '.join(paper_parts)}: {verdict}."
        )
    title = TITLES["table3"]
    return Section(title, [intro, Table(header, rows)], findings)


def figure4_section(results: Path) -> Section:
    title = TITLES["figure4"]
    if not (results / "figure4" / "figure4.png").exists():
        return Section.missing(title, "figure4.py")
    text = (
        "Moving return vs real episodes, mean and 95% band over seeds, per CartPole version "
        "(the Table 2 runs): ![figure 4](figure4/figure4.png) (numbers: `figure4/figure4.csv`)."
    )
    return Section(title, [text])


def figure5_section(data: dict) -> Section:
    intro = (
        f"{data['env']}, K = 1, the Table 2 runs. Training counts imagined steps per LD bin "
        "(width 0.1) every iteration (metric `ld_histogram`); x is the cumulative number of "
        f"imagined steps per seed (bins of {data['step_bin']}; counts of one iteration spread "
        "evenly over the steps it imagined) or the real env steps at which they were imagined. "
        "A2C-Model computes the same LD but does not stop on it. "
        "![figure 5](figure5/figure5.png)"
    )
    header = ["algorithm", "imagined steps per seed", "LD < 0.1", "LD >= 0.9"]
    header += ["LD >= 0.9 in the first 10k imagined steps", "after 10k"]
    header.append("mean LD, first / last 10 iterations")
    pct = lambda v: "–" if v is None else f"{100 * v:.1f}%"
    per_seed = lambda d: sum(d["imagined_steps_per_seed"]) / len(d["imagined_steps_per_seed"])
    rows = [
        [
            algo_name(algo),
            f"{per_seed(d):,.0f}",
            pct(d["fraction_ld_below_0.1"]),
            pct(d["fraction_ld_at_least_0.9"]),
            pct(d["first_10k_fraction_ld_at_least_0.9"]),
            pct(d["after_10k_fraction_ld_at_least_0.9"]),
            f"{d['ld_mean_first_iterations']:.3f} / {d['ld_mean_last_iterations']:.3f}",
        ]
        for algo, d in data["runs"].items()
    ]
    findings = []
    ldn = data["runs"].get("ldn")
    if ldn:
        high = ldn["fraction_ld_at_least_0.9"] or 0.0
        rose = ldn["ld_mean_last_iterations"] > ldn["ld_mean_first_iterations"]
        verdict = (
            "REPRODUCED (most imagined steps have LD near 1)"
            if high > 0.5
            else "NOT reproduced (the paper: LD rises over the first 10k steps, then mostly near 1)"
        )
        model = data["runs"].get("a2c-model")
        if model:
            findings.append(
                f"Imagination: MBRL-LDN imagined {per_seed(ldn):,.0f} steps per seed over "
                f"training, A3C-Model {per_seed(model):,.0f}: with LD this low MBRL-LDN is close "
                "to A3C plus about one imagined step per imagined episode."
            )
        findings.append(
            f"Figure 5: {100 * high:.1f}% of MBRL-LDN's imagined steps have LD >= 0.9 and mean "
            f"LD went from {ldn['ld_mean_first_iterations']:.3f} to "
            f"{ldn['ld_mean_last_iterations']:.3f} ({'up' if rose else 'not up'}): {verdict}."
        )
    title = TITLES["figure5"]
    return Section(title, [intro, Table(header, rows)], findings)


def figure9_section(data: dict) -> Section:
    intro = (
        "MBRL-LDN with K in {0.5, 1, 2} per env: K = 1 is the MBRL-LDN run the other results "
        "read (the same config, trained once), K = 0.5 and 2 one vmapped run; seed s starts "
        "from the same initialisation at every K. On MuJoCo's tasks of a 1M-step budget the "
        'K = 1 runs are the family study\'s: where "The A2C family at the default budgets" '
        "marks its MBRL-LDN row as trained before the task's default changed, that panel is "
        "stale too. ![figure 9](figure9/figure9.png)"
    )
    section = Section(TITLES["figure9"], [intro])
    raw = {(panel["env"], k): p for panel in data["panels"] for k, p in figure9_p(panel).items()}
    adjusted = holm(raw)
    family = sum(p is not None for p in raw.values())
    for panel in data["panels"]:
        section.blocks += [
            f"**{panel['env']}** ({panel['seeds']} seeds, {budget(panel)} each):",
            figure9_table(panel),
        ]
        mine = {k: adjusted[env, k] for env, k in adjusted if env == panel["env"]}
        section.findings += figure9_findings(panel, mine, family)
    pending = data.get("pending", [])
    if pending:
        section.blocks.append(Bullets([f"{p['env']}: pending ({p['reason']})." for p in pending]))
    return section


def figure9_table(panel: dict) -> Table:
    header = ["K", "episodes to threshold: mean ± s.d.", "IQM [95% CI]", "min", "max"]
    header += ["reached", "final moving return: mean ± s.d.", "IQM [95% CI]"]
    header.append("imagined steps per seed")
    header.append("mean LD, last 10 iterations")
    rows = []
    for r in panel["rows"]:
        final = r["final_moving_return"]
        rows.append(
            [
                f"{r['k']:g}",
                pm(r["mean"], r["sd"]),
                iqm(r),
                fmt(r["min"], 0),
                fmt(r["max"], 0),
                f"{r['reached']}/{r['runs']}",
                pm(final["mean"], final["sd"]),
                iqm(final),
                fmt(r["imagined_steps_per_seed"], 0),
                f"{r['ld_mean_last_iterations']:.3f}",
            ]
        )
    return Table(header, rows)


def _figure9_measure(panel: dict) -> tuple[dict, str, str, dict, float | None]:
    """The panel's rows by K, the per-seed key compared, what it is, the mean per K and the
    best K: fewest episodes to threshold, or (no threshold) the highest final moving return
    (None where no K has a mean)."""
    rows = {r["k"]: r for r in panel["rows"]}
    if panel["threshold"] is not None:
        key, pick, what = "episodes_to_threshold", min, "mean episodes to threshold"
        means = {k: r["mean"] for k, r in rows.items() if r["mean"] is not None}
    else:
        key, pick, what = "final_moving_returns", max, "mean final moving return"
        means = {k: r["final_moving_return"]["mean"] for k, r in rows.items()}
        means = {k: m for k, m in means.items() if m is not None}
    best = pick(means, key=means.get) if means else None
    return rows, key, what, means, best


def figure9_p(panel: dict) -> dict[float, float | None]:
    """The raw two-sided Mann-Whitney p of the panel's best K against each other K: the
    comparisons its verdict tests, `{K: p}`."""
    rows, key, _, means, best = _figure9_measure(panel)
    return {k: mann_whitney_p(rows[best][key], rows[k][key]) for k in means if k != best}


def figure9_findings(
    panel: dict, adjusted: dict[float, float | None] | None = None, family: int | None = None
) -> list[str]:
    """Which K is best: fewest episodes to threshold, or (no threshold) the highest final
    moving return; with Mann-Whitney tests of the best against the others, Holm-adjusted over
    the figure's `family` of comparisons (`adjusted`: per K; without it, over this panel's).
    The verdict reads the adjusted p and says its power, as Table 5's does: REPRODUCED only
    where K = 1 is best and significantly so against each other K (adjusted p < 0.05); NOT
    reproduced where another K is significantly better than K = 1 at the paper's budget;
    otherwise inconclusive, with the budget where it is below the paper's."""
    rows, _, what, means, best = _figure9_measure(panel)
    if best is None:
        return []
    raw = figure9_p(panel)
    if adjusted is None:
        adjusted = holm(raw)
        family = sum(p is not None for p in raw.values())
    trained = [r["episodes_per_seed"] for r in panel["rows"] if "episodes_per_seed" in r]
    if trained:  # the episodes the runs took; the least-trained K sets the budget's power
        short = inconclusive(panel["env"], min(trained))
    else:  # older files: the budget
        steps = panel.get("steps")
        if "steps" not in panel and panel.get("budget", "").endswith(" steps"):
            steps = float(panel["budget"].split()[0].replace(",", ""))
        short = inconclusive(panel["env"], None if steps else panel.get("episodes"), steps)
    text = ", ".join(f"K={k:g}: {m:.0f}" for k, m in means.items())
    p = {k: adjusted.get(k) for k in raw}
    tests = [
        f"K={best:g} vs K={k:g}: p = {raw[k]:.2g}, adjusted {p[k]:.2g}"
        for k in raw
        if raw[k] is not None
    ]
    noise = f" (Mann-Whitney, Holm over {family} comparisons: {'; '.join(tests)})" if tests else ""
    others = [k for k in means if k != best]
    shown = bool(others) and all(p[k] is not None and p[k] < 0.05 for k in others)
    worse = best != 1.0 and 1.0 in means and p[1.0] is not None and p[1.0] < 0.05
    reversal = f"K={best:g} significantly better; the paper: K = 1 best" if worse else None
    seeds = rows[best]["runs"]
    verdict = powered_verdict(
        "K = 1 best", "K = 1 slightly best", best == 1.0, shown, reversal, short, seeds
    )
    return [f"Figure 9, {panel['env']}: {what} {text}; best K={best:g}{noise}: {verdict}."]
