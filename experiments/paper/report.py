"""REPORT.md from the result files: every table beside the paper's numbers, what reproduced
and what did not, the machine and the commands.

    python experiments/paper/report.py [--scale cpu|paper] [--smoke] [--results DIR]

Reads DIR/<result>/*.json (a result not produced yet is reported as missing) and writes
DIR/REPORT.md. It trains nothing.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from scipy import stats

from experiments import stats as iqm_stats
from experiments.paper import common

NAMES = (
    "table2",
    "table3",
    "figure5",
    "figure9",
    "calibration",
    "readings",
    "rules",
    "table4",
    "table5",
    "targets",
)


def load(results: Path) -> dict[str, dict | None]:
    out = {}
    for name in NAMES:
        path = results / name / f"{name}.json"
        out[name] = json.loads(path.read_text()) if path.exists() else None
    return out


def fmt(value, digits: int = 1) -> str:
    if value is None:
        return "–"
    if isinstance(value, int):
        return f"{value:,}"
    return f"{value:,.{digits}f}"


def pm(mean, sd, digits: int = 1) -> str:
    if mean is None:
        return "–"
    return f"{fmt(mean, digits)} ± {fmt(sd, digits)}" if sd is not None else fmt(mean, digits)


def iqm(record: dict, digits: int = 0) -> str:
    """A record's IQM with its bootstrap 95% interval, `512 [480, 540]` ("–" in result files
    from before the IQM)."""
    return iqm_stats.text({"iqm": record.get("iqm"), "ci95": record.get("ci95")}, digits)


def better(x: list, y: list, lower_is_better: bool) -> str:
    """The probability that a seed of X does better than a seed of Y, with its bootstrap
    95% interval, over the values that are not None."""
    x, y = [v for v in x if v is not None], [v for v in y if v is not None]
    value = iqm_stats.improvement(x, y, lower_is_better=lower_is_better)
    return f"P(better) = {iqm_stats.improvement_text(value)}"


def algo_name(algo: str) -> str:
    return common.PAPER_ALGOS.get(algo, algo)


# -- the records a section is made of, and their one renderer -------------------------------------


@dataclass
class Table:
    """A markdown table: a header row and rows of already formatted cells."""

    header: list[str]
    rows: list[list[str]] = field(default_factory=list)


@dataclass
class Bullets:
    items: list[str]


@dataclass
class Section:
    """One `##` section of the report: its blocks (paragraphs, tables, bullet lists; figures
    are linked from the paragraphs) and the findings it adds to the summary at the top."""

    title: str
    blocks: list[str | Table | Bullets] = field(default_factory=list)
    findings: list[str] = field(default_factory=list)

    @classmethod
    def missing(cls, title: str, script: str) -> Section:
        """A section whose result file is not there yet."""
        return cls(title, [f"Not produced yet (run `{script}`)."])


def markdown_table(table: Table) -> list[str]:
    """`| a | b |` lines: the header, the separator, one line per row."""
    line = lambda cells: "| " + " | ".join(cells) + " |"
    return [line(table.header), "|" + "---|" * len(table.header), *map(line, table.rows)]


def render_section(section: Section) -> list[str]:
    lines = [f"## {section.title}", ""]
    for block in section.blocks:
        if isinstance(block, Table):
            lines += markdown_table(block)
        elif isinstance(block, Bullets):
            lines += [f"- {item}" for item in block.items]
        else:
            lines.append(block)
        lines.append("")
    return lines


def mann_whitney_p(x: list, y: list) -> float | None:
    """Two-sided Mann-Whitney p over the values that are not None (None: too few, < 2 each).
    The report's one significance test."""
    x, y = [v for v in x if v is not None], [v for v in y if v is not None]
    if len(x) < 2 or len(y) < 2:
        return None
    return float(stats.mannwhitneyu(x, y).pvalue)


def mann_whitney(x: list, y: list) -> str:
    p = mann_whitney_p(x, y)
    return "too few runs to test" if p is None else f"Mann-Whitney p = {p:.2g}"


def budget(record: dict) -> str:
    """A run's budget per seed as its result file states it (files from before step
    budgets give episodes only)."""
    return record.get("budget") or f"{record['episodes']:,} episodes"


# -- sections ------------------------------------------------------------------------------------


def setup(data: dict, scale: common.Scale) -> Section:
    first = next((d for d in data.values() if d), None)
    machine = first["machine"] if first else common.machine()
    flag = "--smoke" if scale.name == "smoke" else f"--scale {scale.name}"
    run = "make paper" + ("" if scale.name == "cpu" else f" SCALE={scale.name}")
    if scale.name == "smoke":
        run = "python experiments/paper/all.py --smoke"
    budgets = {
        env: ", ".join(f"{n:,} {unit}" for unit, n in b.items())
        for env, b in scale.mujoco_budgets.items()
    }
    left_out = [env for env in common.MUJOCO if env not in budgets]
    mujoco = (
        f"{scale.mujoco_seeds} seeds per run (the native MuJoCo engine on CPU); budgets per "
        "seed "
        + ", ".join(f"{env} {b}" for env, b in budgets.items())
        + (f"; pending at this scale: {', '.join(left_out)}." if left_out else ".")
        if budgets
        else "not run at this scale."
    )
    scripts = ("table2", "table3", "figure4", "figure5", "figure9", "calibration")
    items = [
        f"Scale `{scale.name}`: {scale.seeds} seeds per run (vmapped: one compiled program per "
        f"run), a budget of {scale.episodes:,} real episodes per seed (summed over "
        f"{scale.workers} synchronous workers), the `paper` preset (PAPER.md), K = 1 unless "
        "stated. Episodes to threshold count real episodes in completion order; a run that never "
        "reaches the threshold within the budget is left out of mean and s.d. and counted in "
        "*reached*.",
        "Statistics (Agarwal et al., NeurIPS 2021): *IQM* is the interquartile mean over seeds "
        "(the mean of the middle half), with a bootstrap 95% interval (2,000 resamples, "
        "percentile; `experiments/stats.py`, scipy); *P(better)* is the probability that a "
        "seed of the first algorithm does better than a seed of the second (fewer episodes, or "
        "a higher return), with its bootstrap interval; 0.5 is a tie. The paper's own columns "
        "(mean ± s.d.) are kept beside them. `ldn-jax compare RUN_DIR ...` prints the same for "
        "any runs.",
        f"MuJoCo (Tables 4 and 5, Figure 9's MuJoCo panels): {mujoco}{mujoco_time(data)}",
        f"Machine: {machine['cpu']}, {machine['cores']} cores, JAX backend "
        f"{machine['jax_backend']}; jax {machine['jax']}, jaxlib {machine['jaxlib']}, Python "
        f"{machine['python']}; results dated {dated(data) or machine['date']}. The CPU was "
        "shared with other jobs, so seconds are indicative.",
        f"Commands: `{run}` (that is, `python experiments/paper/all.py {flag}`), "
        "or one script at a time: "
        + ", ".join(f"`python experiments/paper/{n}.py {flag}`" for n in scripts)
        + ", then `table4.py`, `table5.py` and `report.py` the same way. `--scale paper` "
        "raises the budget to 4,000 episodes and the calibration samples; `--smoke` is the "
        "tests' tiny budget. Training runs are kept under `runs/<scale>/` (not in git) and "
        "reused when their config matches.",
    ]
    return Section("Setup", [Bullets(items)])


def dated(data: dict) -> str:
    """When each result file was made: "2026-12-01" or "2026-11-22 (table2, ...), 2026-12-01
    (table4, ...)"; "" without files."""
    by_date: dict[str, list[str]] = {}
    for name, d in data.items():
        if d and "machine" in d:
            by_date.setdefault(d["machine"]["date"], []).append(name)
    if len(by_date) < 2:
        return next(iter(by_date), "")
    return ", ".join(f"{date} ({', '.join(names)})" for date, names in sorted(by_date.items()))


def mujoco_time(data: dict) -> str:
    """The sentence giving the MuJoCo runs' wall time in the result files (training and
    compile, summed over runs; each run's seeds and K are one vmapped program), or ""."""
    runs = [r for r in (data.get("table4") or {}).get("rows", []) if r["status"] == "done"]
    runs += [r for r in (data.get("table5") or {}).get("rows", []) if r["status"] == "done"]
    panels = [p for p in (data.get("figure9") or {}).get("panels", []) if p["env"] in common.MUJOCO]
    timed = [*runs, *(p for p in panels if "train_seconds" in p)]
    if not timed:
        return ""
    seconds = sum(r["train_seconds"] + r["compile_seconds"] for r in timed)
    return (
        f" Wall time of these {len(timed)} runs: {seconds / 60:.0f} minutes of training and "
        "compile in all (evaluation and the scripts' own work not counted)."
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


def _by_env(rows: list[dict]) -> dict[str, dict[str, dict]]:
    out: dict[str, dict[str, dict]] = {}
    for r in rows:
        if r["status"] == "done":
            out.setdefault(r["env"], {})[r["algo"]] = r
    return out


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
    for env, algos in _by_env(rows).items():
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
    for env, algos in _by_env(table["rows"]).items():
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
        "MBRL-LDN with K in {0.5, 1, 2}, one vmapped run per env (the same initialisations for "
        "every K). ![figure 9](figure9/figure9.png)"
    )
    section = Section(TITLES["figure9"], [intro])
    for panel in data["panels"]:
        section.blocks += [
            f"**{panel['env']}** ({panel['seeds']} seeds, {budget(panel)} each):",
            figure9_table(panel),
        ]
        section.findings += figure9_findings(panel)
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


def figure9_findings(panel: dict) -> list[str]:
    """Which K is best: fewest episodes to threshold, or (no threshold) the highest final
    moving return; with Mann-Whitney tests of the best against the others."""
    rows = {r["k"]: r for r in panel["rows"]}
    if panel["threshold"] is not None:
        key, better, what = "episodes_to_threshold", min, "mean episodes to threshold"
        means = {k: r["mean"] for k, r in rows.items() if r["mean"] is not None}
    else:
        key, better, what = "final_moving_returns", max, "mean final moving return"
        means = {k: r["final_moving_return"]["mean"] for k, r in rows.items()}
        means = {k: m for k, m in means.items() if m is not None}
    if not means:
        return []
    best = better(means, key=means.get)
    verdict = (
        "REPRODUCED (K = 1 best, as in the paper)"
        if best == 1.0
        else "NOT reproduced (the paper: K = 1 slightly best)"
    )
    text = ", ".join(f"K={k:g}: {m:.0f}" for k, m in means.items())
    tests, significant = [], False
    for k in means:
        p = None if k == best else mann_whitney_p(rows[best][key], rows[k][key])
        if p is not None:
            significant |= p < 0.05
            tests.append(f"K={best:g} vs K={k:g}: p = {p:.2g}")
    noise = f" (Mann-Whitney {'; '.join(tests)})" if tests else ""
    if tests and not significant:
        verdict += "; the differences are within seed-to-seed noise"
    return [f"Figure 9, {panel['env']}: {what} {text}; best K={best:g}{noise}: {verdict}."]


def calibration_section(data: dict) -> Section:
    intro = (
        f"MBRL-LDN on {data['env']}, K = 1, {data['seeds']} seeds, "
        f"{data['imagined_episodes_per_seed']} imagined episodes per seed at each point, played "
        "in M1 with the sampled policy from fresh initial states while the real JAX CartPole is "
        "stepped alongside (`ldn_jax/calibration.py`). Errors: " + data["errors"] + ". Steps: "
        "every imagined step before predicted termination (the LD stop not applied; the "
        "compounding error only while the real shadow episode runs). Expected "
        + data["expected"]
        + ". The ensemble: E models of M1's architecture "
        "fitted from fresh initialisations on the final real buffer, as many steps as M1; its "
        "learning degree is "
        + data["ensemble_ld"]
        + ". ![calibration](calibration/calibration.png)"
    )
    num = lambda v: "–" if v is None else f"{v:.3f}"
    scores = Table(
        [
            "episodes",
            "steps",
            "Spearman LD vs 1-step error",
            "AUC of LD",
            "AUC of 1 - LD",
            "Pearson LD vs 1-step",
            "Spearman LD vs compounding",
            "Spearman disagreement vs 1-step",
            "AUC of disagreement",
            "mean LD",
            "mean sigma2",
            "reward's share of sigma2",
        ]
    )
    for p in data["points"]:
        im = p["pooled"]["imagined"]
        one, comp = im["one_step_error"], im["compounding_error"]
        auc = one["ld"]["auc_error_above_median"]
        scores.rows.append(
            [
                f"{p['episodes']:,}",
                f"{im['steps']:,}",
                num(one["ld"]["spearman"]),
                num(auc),
                num(None if auc is None else 1 - auc),
                num(one["ld"]["pearson"]),
                num(comp["ld"]["spearman"]),
                num(one["disagreement"]["spearman"]),
                num(one["disagreement"]["auc_error_above_median"]),
                num(im["ld"]["mean"]),
                num(im["ld"].get("sigma2_mean")),
                num(im["ld"].get("sigma2_reward_share")),
            ]
        )
    horizons_intro = (
        "Imagined horizons (episode lengths in M1) under three stopping rules: predicted "
        "termination only (A3C-Model), the LD draw (MBRL-LDN), and the same draw with the "
        "ensemble's learning degree:"
    )
    horizons = Table(
        [
            "episodes",
            "predicted termination: mean / median / p90",
            "LD rule: mean / median / p90 / max",
            "ensemble rule: mean / median",
            "mean ensemble LD",
            "ensemble final loss",
        ]
    )
    for p in data["points"]:
        h = p["pooled"]["horizons"]
        ens_ld = p["pooled"]["imagined"].get("ensemble_ld", {}).get("mean")
        a, b, c = h["predicted_termination"], h["ld_rule"], h["ensemble_rule"]
        horizons.rows.append(
            [
                f"{p['episodes']:,}",
                f"{a['mean']:.1f} / {a['median']:.0f} / {a['p90']:.0f}",
                f"{b['mean']:.2f} / {b['median']:.0f} / {b['p90']:.0f} / {b['max']}",
                f"{c['mean']:.1f} / {c['median']:.0f}",
                num(ens_ld),
                f"{p['ensemble']['final_loss_mean']:.2e}",
            ]
        )
    sources = "; ".join(f"{p['episodes']:,}: {p['source']}" for p in data["points"])
    blocks = [intro, scores, horizons_intro, horizons, f"Sources of the states: {sources}."]
    training = data.get("training", [])
    if training:
        blocks.append(
            "Training with each estimator (the same config and seeds; `--ld ensemble` with "
            f"E = {training[-1]['ensemble_members']} members):"
        )
        header = ["learning degree", "episodes to threshold: mean ± s.d.", "min", "max"]
        header += ["reached", "mean LD, last 10 iterations", "imagined steps per real step"]
        header.append("train s")
        rows = [
            [
                "M1 vs M0 (the paper)" if r["ld"] == "m0" else "ensemble disagreement",
                pm(r["mean"], r["sd"]),
                fmt(r["min"], 0),
                fmt(r["max"], 0),
                f"{r['reached']}/{r['runs']}",
                f"{r['ld_mean_last_iterations']:.3f}",
                f"{r['imagined_steps_per_real_step']:.2f}",
                f"{r['train_seconds']:.0f}",
            ]
            for r in training
        ]
        blocks.append(Table(header, rows))
    title = TITLES["calibration"]
    return Section(title, blocks, calibration_findings(data))


def calibration_findings(data: dict) -> list[str]:
    training = data.get("training", [])
    findings = []
    last = data["points"][-1]
    one = last["pooled"]["imagined"]["one_step_error"]
    auc = one["ld"]["auc_error_above_median"]
    if auc is None:
        return findings
    if auc < 0.45:
        how = "LD is lower where the model is more wrong, as the method assumes"
    elif auc > 0.55:
        how = "LD is HIGHER where the model is more wrong, the opposite of the method's premise"
    else:
        how = "LD barely separates high-error from low-error steps"
    d_auc = one["disagreement"]["auc_error_above_median"]
    ens = ""
    if d_auc is not None:
        flags = "it flags high error" if d_auc > 0.55 else "it does not flag high error"
        ens = f"; the ensemble disagreement's AUC is {d_auc:.3f} ({flags})"
    h = last["pooled"]["horizons"]["ld_rule"]
    for population, where in (
        ("ld_rule", "the steps MBRL-LDN imagines"),
        ("imagined", "whole imagined episodes (run to predicted termination)"),
    ):
        ld = last["pooled"][population]["ld"]
        if not ld.get("sigma2_mean"):
            continue
        # tanh(K sigma2 / 2) = 0.9 at K sigma2 = 2 artanh(0.9) = 2.944.
        findings.append(
            f"Why LD stays low ({where}, {last['episodes']:,} episodes): M1 deviates from "
            f"M0 by sigma2 = {ld['sigma2_mean']:.3f} on average, "
            f"{100 * ld['sigma2_reward_share']:.0f}% of it in the reward output; LD = "
            f"tanh(K sigma2 / 2) averages {ld['mean']:.3f}, so a step stops with "
            f"probability about {1 - ld['mean']:.2f}. LD = 0.9 at that sigma2 would need "
            f"K = {2.944 / ld['sigma2_mean']:.0f}."
        )
    ens_ld = last["pooled"]["imagined"].get("ensemble_ld", {}).get("mean")
    if ens_ld is not None:
        e = last["pooled"]["horizons"]["ensemble_rule"]
        findings.append(
            f"Ensemble learning degree (the estimator of `--ld ensemble`, K = 1, "
            f"disagreement relative to the members' fit error) at {last['episodes']:,} "
            f"episodes: it averages {ens_ld:.3f} over imagined steps (M1-vs-M0 LD: "
            f"{last['pooled']['imagined']['ld']['mean']:.3f}), so its rule imagines "
            f"{e['mean']:.1f} steps per episode on average (median {e['median']:.0f}) "
            f"against the LD rule's {h['mean']:.2f}."
        )
    rows = {r["ld"]: r for r in training}
    if {"m0", "ensemble"} <= set(rows) and rows["m0"]["mean"] and rows["ensemble"]["mean"]:
        ours, trained = rows["m0"], rows["ensemble"]
        test = mann_whitney(ours["episodes_to_threshold"], trained["episodes_to_threshold"])
        cost = trained["train_seconds"] / max(ours["train_seconds"], 1e-9)
        per_step = "imagined_steps_per_real_step"
        findings.append(
            f"Training with the ensemble learning degree on {data['env']}: "
            f"{trained['mean']:.0f} ± {trained['sd'] or 0:.0f} episodes to threshold "
            f"({trained['reached']}/{trained['runs']} reached) vs {ours['mean']:.0f} ± "
            f"{ours['sd'] or 0:.0f} with M1 vs M0 ({test}); it imagines "
            f"{trained[per_step]:.2f} steps per real step (M1 vs M0: "
            f"{ours[per_step]:.2f}) at {cost:.1f}x the training time."
        )
    findings.append(
        f"LD calibration at {last['episodes']:,} episodes: AUC of LD for high one-step error "
        f"{auc:.3f} (1 - LD: {1 - auc:.3f}): {how}{ens}. The LD rule's imagined episodes "
        f"last {h['mean']:.2f} steps on average (median {h['median']:.0f})."
    )
    return findings


def _versus(row: dict) -> tuple[str, str]:
    """P(better than A3C-Model) with its interval and Mann-Whitney's p, and the verdict."""
    versus = row.get("vs_a3c_model")
    if versus is None:
        return "(baseline)", "baseline"
    p_better = iqm_stats.improvement_text(versus["p_better"])
    return f"{p_better}, p = {versus['mann_whitney_p']:.2g}", versus["verdict"]


VERDICTS = ("helps", "hurts", "no clear difference")


def readings_section(data: dict) -> Section:
    unit = data["unit"].replace("_", " ")
    intro = (
        f"{data['env']}, MBRL-LDN, K = 1, {data['seeds']} seeds, {budget(data)} each "
        "(`experiments/paper/stops.py`). Eq. 3's square (M1 - M0)^2 reduced over the model's "
        "5 outputs by the mean (the literal reading, the `paper` preset) or the sum, over the "
        "step's own prediction or a window of the episode's last 10 imagined steps (the "
        'paper: "the input size is 10 batches"), or over a batch of 10 samples (the sum '
        "times 10: `ld_scale`), and the literal reading with the model taking actions as "
        "forces (Table 1) instead of one-hot. Against A3C-Model (no stop): "
        "the probability that a seed of the reading reaches the threshold sooner (a seed "
        "that never does counts as the budget + 1), with its bootstrap 95% interval, and "
        "the Mann-Whitney p. Figure 5 redrawn for each reading: "
        "![readings](readings/readings.png)"
    )
    header = ["reading", "mean LD", "LD >= 0.9, first 10k imagined steps", "after 10k"]
    header += ["imagined steps per episode", "reached", f"{unit} to threshold: IQM [95% CI]"]
    header += ["mean ± s.d.", "vs A3C-Model: P(sooner), p", "verdict"]
    pct = lambda v: "–" if v is None else f"{100 * v:.1f}%"
    rows = []
    for r in data["readings"].values():
        sooner, verdict = _versus(r)
        t = r["to_threshold"]
        rows.append(
            [
                r["title"],
                "–" if r["ld_mean"] is None else f"{r['ld_mean']:.3f}",
                pct(r.get("first_10k_fraction_ld_at_least_0.9")),
                pct(r.get("after_10k_fraction_ld_at_least_0.9")),
                iqm(r["imagined_per_episode"], 1),
                f"{r['reached']}/{r['runs']}",
                iqm(t),
                pm(t["mean"], t["sd"], 0),
                sooner,
                verdict,
            ]
        )
    findings = []
    readings = {n: r for n, r in data["readings"].items() if n != "a3c-model"}
    if readings:
        near_one = max(readings, key=lambda n: readings[n]["ld_mean"] or 0.0)
        best = min(readings, key=lambda n: readings[n]["to_threshold"]["iqm"] or float("inf"))
        base = data["readings"].get("a3c-model")
        base_text = f"; A3C-Model {iqm(base['to_threshold'])}" if base else ""
        findings.append(
            f"Readings of eq. 3 ({data['env']}): mean LD "
            + ", ".join(f"{r['title']} {r['ld_mean'] or 0:.2f}" for r in readings.values())
            + f"; the highest under {readings[near_one]['title']}. Fewest {unit} to threshold: "
            f"{readings[best]['title']}, IQM {iqm(readings[best]['to_threshold'])}{base_text}. "
            + "Against A3C-Model: "
            + "; ".join(f"{r['title']} {_versus(r)[1]}" for r in readings.values())
            + "."
        )
    return Section(TITLES["readings"], [intro, Table(header, rows)], findings)


def rules_section(data: dict) -> Section:
    intro = (
        "Every rule ends an imagined episode after the step it judges, as a truncation (the "
        "critic bootstraps), as Algorithm 1's LD draw does: rules differ only in when they "
        "stop (`--stop`, `ldn_jax/imagination.py`). ld: the draw with P(stop) = 1 - LD (the "
        "literal and the Figure 5 reading of eq. 3, and the ensemble estimator); m2ac: of the "
        "running imagined rollouts only the `m2ac_keep` share with the lowest ensemble "
        "disagreement goes on at each step (M2AC's rank mask, Pan et al. 2020; 8 workers make "
        "a small batch to rank); horizon: cut after h steps (MBPO's rollout length); oracle: "
        "stop where the true one-step error ||M1(s, a) - env(s, a)|| exceeds a threshold, the "
        "real env stepped from the imagined state (the ceiling an estimator could reach; "
        "CartPole only: a MuJoCo observation is not its whole state); none: A3C-Model. The "
        "M2AC share and the oracle threshold are each one vmapped program over their values. "
        "K = 1. Verdicts compare each rule with A3C-Model on the steps (MuJoCo) or episodes "
        "(CartPole) to threshold: helps where the 95% interval of P(sooner) lies above 0.5, "
        "hurts where it lies below. Seconds to threshold were measured with other jobs on "
        "the 2 cores: compare them loosely. ![rules](rules/rules.png)"
    )
    section = Section(TITLES["rules"], [intro])
    for env, panel in data["envs"].items():
        unit = panel["unit"].replace("_", " ")
        header = ["rule", "reached", f"{unit} to threshold: IQM [95% CI]"]
        header += ["final moving return", "imagined per real step", "seconds to threshold"]
        header += ["vs A3C-Model: P(sooner), p", "verdict"]
        rows, verdicts = [], {}
        for r in panel["rows"]:
            if "label" not in r:
                rows.append([r["title"], r["status"], *["–"] * (len(header) - 2)])
                continue
            sooner, verdict = _versus(r)
            verdicts.setdefault(verdict, []).append(r["label"])
            rows.append(
                [
                    r["label"],
                    f"{r['reached']}/{r['runs']}",
                    iqm(r["to_threshold"]),
                    iqm(r["final_moving_return"]),
                    iqm(r["imagined_per_real_step"], 3),
                    iqm(r["seconds_to_threshold"], 1),
                    sooner,
                    verdict,
                ]
            )
        size = f"{panel['seeds']} seeds, {panel['budget']:,} {unit.split()[-1]} each"
        if panel.get("threshold") is not None:
            size += f", threshold {panel['threshold']:g} on the moving return"
        section.blocks += [f"**{env}** ({size}):", Table(header, rows)]
        named = {v: ", ".join(verdicts.get(v, [])) or "no rule" for v in VERDICTS}
        section.findings.append(
            f"Stopping rules, {env}, against A3C-Model in {unit} to threshold: helps: "
            f"{named['helps']}; hurts: {named['hurts']}; no clear difference: "
            f"{named['no clear difference']}."
        )
    return section


def _pending_note(table: dict) -> list[str]:
    pending = [r for r in table["rows"] if r["status"] != "done"]
    if not pending:
        return []
    names = sorted({r["env"] for r in pending}, key=[r["env"] for r in pending].index)
    reason = pending[0]["reason"].removeprefix(f"{pending[0]['env']} ")
    return [f"Pending at this scale ({reason}): {', '.join(names)}."]


def table4_section(table: dict) -> Section:
    intro = (
        f'Final moving return (our reading of "total moving reward"), {table["seeds"]} seeds '
        "per run, continuous actions (the model predicts standardised state deltas; README). "
        "The paper's values exceed what some tasks can score, so compare the two "
        "algorithms, not the values. Curves: ![table 4](table4/table4.png)"
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
    findings = []
    for env, algos in _by_env(done).items():
        if set(algos) != {"a2c-model", "ldn"}:
            continue
        model, ldn = algos["a2c-model"], algos["ldn"]
        x, y = ldn["final_moving_returns"], model["final_moving_returns"]
        p, test = mann_whitney_p(x, y), mann_whitney(x, y)
        if p is None or p >= 0.05:
            verdict = "no significant difference (the paper: MBRL-LDN higher): NOT reproduced"
        elif ldn["mean"] > model["mean"]:
            verdict = "REPRODUCED (MBRL-LDN higher, as in the paper)"
        else:
            verdict = "NOT reproduced: A3C-Model higher (the paper: MBRL-LDN higher)"
        findings.append(
            f"Table 4, {env} ({budget(ldn)}): MBRL-LDN {ldn['mean']:.1f} vs "
            f"A3C-Model {model['mean']:.1f} final moving return ({test}, "
            f"{better(x, y, False)}; paper "
            f"{ldn['paper']} vs {model['paper']}): {verdict}."
        )
    title = TITLES["table4"]
    return Section(title, [intro, Table(header, rows), *_pending_note(table)], findings)


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
    findings = [table5_finding(env, algos) for env, algos in _by_env(done).items()]
    title = TITLES["table5"]
    return Section(title, [intro, Table(header, rows), *_pending_note(table)], findings)


def table5_finding(env: str, algos: dict[str, dict]) -> str:
    means = {a: r["mean"] for a, r in algos.items() if r["mean"] is not None}
    if not means:
        return f"Table 5, {env}: no run reached the top within the budget."
    order = sorted(means, key=means.get)
    ours = " < ".join(f"{algo_name(a)} ({means[a]:.0f})" for a in order)
    reached = ", ".join(f"{algo_name(a)} {r['reached']}/{r['runs']}" for a, r in algos.items())
    verdict = (
        "REPRODUCED (PPO2-LDN fewest, as in the paper)"
        if order[0] == "ppo-ldn" and len(means) == len(algos)
        else "NOT reproduced (the paper: PPO2-LDN fewest)"
    )
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
        + mann_whitney(algos["ppo-ldn"]["episodes_to_top"], algos[a]["episodes_to_top"])
        + ", "
        + better(algos["ppo-ldn"]["episodes_to_top"], algos[a]["episodes_to_top"], True)
        for a in ("ppo", "ppo-model")
        if a in algos and "ppo-ldn" in algos
    )
    imagined = ", ".join(
        f"{algo_name(a)} {r['imagined_steps_per_seed']:,.0f}"
        + (
            f" (mean LD {r['ld_mean_last_iterations']:.2f})"
            if r.get("ld_mean_last_iterations") is not None and a.endswith("ldn")
            else ""
        )
        for a, r in algos.items()
        if r.get("imagined_steps_per_seed")
    )
    imagined = f" Imagined steps per seed: {imagined}." if imagined else ""
    return (
        f"Table 5, {env}: mean episodes to the top {ours} ({tests}). Reached: "
        f"{reached}{unreached}: {verdict}.{imagined}"
    )


def _span(values: list, digits: int = 0) -> str:
    """ "low to high" of the values given, "all N" where they are equal."""
    have = [v for v in values if v is not None]
    if not have:
        return "–"
    if min(have) == max(have):
        return f"{have[0]:,.{digits}f} (all {len(have)})"
    return f"{min(have):,.{digits}f} to {max(have):,.{digits}f}"


def targets_section(record: dict) -> Section:
    intro = (
        "What the defaults deliver (not a table of the paper): each run at its default budget "
        "(`DEFAULT_STEPS`), as `python experiments/run.py --env ENV --algo ALGO --seeds N` "
        "starts it. Curves: ![targets](targets/targets.png)"
    )
    rows = [r for r in record["rows"] if r["status"] == "done"]
    pendulum = [r for r in rows if r["env"] == "inverted_pendulum"]
    cheetah = [r for r in rows if r["env"] == "halfcheetah"]
    parts: list = [intro]
    findings = []
    if pendulum:
        header = ["algorithm", "budget", "seeds >= 900", "env steps to 900", "highest"]
        header += ["final moving return", "greedy eval", "training s", "target met"]
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
        header += ["final, per run", "greedy eval, mean", "wall s", "target", "met"]
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
                    f"{r['wall_seconds']:.0f}",
                    target.get(r["algo"], ""),
                    "yes" if r["met"] else "NO",
                ]
            )
            findings.append(
                f"Targets, halfcheetah {r['algo']}: mean moving return "
                f"{r['first_mean_moving_return']:,.0f} -> {r['final_mean_moving_return']:,.0f} "
                f"over {runs} runs in {r['wall_seconds'] / 60:.0f} minutes "
                f"({target.get(r['algo'], '')}: {'met' if r['met'] else 'NOT met'})."
            )
        parts.append(Table(header, table))
    pending = [r for r in record["rows"] if r["status"] != "done"]
    if pending:
        parts.append(
            "Pending at this scale: " + ", ".join(f"{r['env']} {r['algo']}" for r in pending) + "."
        )
    return Section(TITLES["targets"], parts, findings)


SECTIONS = (
    ("table2", table2_section),
    ("table3", table3_section),
    ("figure4", None),  # a figure only: `figure4_section` looks for it
    ("figure5", figure5_section),
    ("figure9", figure9_section),
    ("calibration", calibration_section),
    ("readings", readings_section),
    ("rules", rules_section),
    ("table4", table4_section),
    ("table5", table5_section),
    ("targets", targets_section),
)
"""The report's sections in order: result name -> builder of its `Section` from the result."""

TITLES = {
    "table2": "Table 2: episodes to threshold",
    "figure4": "Figure 4: learning curves",
    "table3": "Table 3: wall-clock seconds to threshold",
    "figure5": "Figure 5: learning degree over imagined steps",
    "figure9": "Figure 9: the gain K",
    "calibration": "LD calibration: does the learning degree know when the model is wrong?",
    "readings": "The readings of eq. 3",
    "rules": "Stopping rules for imagination, side by side",
    "table4": "Table 4: MuJoCo, A3C-Model vs MBRL-LDN",
    "table5": "Table 5: MuJoCo, PPO2 vs PPO2-Model vs PPO2-LDN",
    "targets": "MuJoCo at the default budgets: the project's targets",
}
"""Every section's title."""


def sections(results: Path, data: dict) -> list[Section]:
    out = []
    for name, build in SECTIONS:
        if build is None:
            out.append(figure4_section(results))
        elif data[name] is None:
            out.append(Section.missing(TITLES[name], f"{name}.py"))
        else:
            out.append(build(data[name]))
    return out


def render(results: Path, scale: common.Scale) -> str:
    """The report; `scale` is used only where no result file says which scale made it."""
    data = load(results)
    made = {d["scale"] for d in data.values() if d}
    if len(made) == 1:
        scale = common.SCALES[made.pop()]
    body = sections(results, data)
    summary = Section(
        "What reproduced and what did not",
        [Bullets([f for section in body for f in section.findings])],
    )
    lines = [
        "# Reproduction report: MBRL-LDN on CartPole and MuJoCo",
        "",
        "Generated by `experiments/paper/report.py` from the result files beside it; do not "
        "edit by hand. The paper's numbers are those of `shared/PAPER.md`.",
        "",
    ]
    for section in (setup(data, scale), summary, *body):
        lines += render_section(section)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    scale, results = common.parse_args(argv, __doc__)
    results.mkdir(parents=True, exist_ok=True)
    (results / "REPORT.md").write_text(render(results, scale))
    print(f"wrote {results / 'REPORT.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
