"""REPORT.md's building blocks: the `Section` a result becomes (paragraphs, a `Table`,
`Bullets`) and its markdown, the numbers' formats, the statistics' sentences, and every
section's title (`TITLES`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from scipy import stats

from experiments.paper import common
from ldn_jax.host import stats as iqm_stats


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


def holm(pvalues: dict) -> dict:
    """Holm-adjusted p per key over the keys that have a p (`iqm_stats.holm`: the family is
    every comparison given that was tested); a key whose p is None stays None."""
    tested = [key for key, p in pvalues.items() if p is not None]
    adjusted = dict(zip(tested, iqm_stats.holm([pvalues[k] for k in tested]), strict=True))
    return {key: adjusted.get(key) for key in pvalues}


def adjusted_text(p: float | None, adjusted: float | None, family: str) -> str:
    """ "Mann-Whitney p = 0.016, Holm-adjusted over 6 tasks 0.095": the raw two-sided p and
    the adjusted one the verdict reads ("too few runs to test" without a p)."""
    if p is None:
        return "too few runs to test"
    return f"Mann-Whitney p = {p:.2g}, Holm-adjusted over {family} {adjusted:.2g}"


PAPER_MUJOCO_EPISODES = 1_734
"""The fewest episodes the paper trained a MuJoCo run for: Table 5's tops came after 1,734 to
2,603 episodes (of up to 1,000 steps each); Table 4 and Figure 9 state no budget."""


def inconclusive(env: str, episodes: float | None = None, steps: float | None = None) -> str | None:
    """ "inconclusive at this budget (...)" for a MuJoCo run trained for fewer episodes than
    the paper's, where a difference the paper found may simply not have appeared yet; None
    where the budget is the paper's or more (or the env is CartPole). `steps` bounds the
    episodes from above (an episode lasts at most 1,000 steps) where they are not known."""
    if env not in common.MUJOCO:
        return None
    if episodes is None and steps is not None:
        episodes = steps / 1_000
    if episodes is None or episodes >= PAPER_MUJOCO_EPISODES:
        return None
    share = episodes / PAPER_MUJOCO_EPISODES
    return (
        f"inconclusive at this budget ({episodes:,.0f} episodes per seed, {share:.0%} of the "
        f"paper's >= {PAPER_MUJOCO_EPISODES:,})"
    )


def too_wide(x: list, y: list, lower_is_better: bool = False) -> str | None:
    """ "inconclusive at N seeds (...)" where the bootstrap 95% interval of P(X better than Y)
    includes 0.5: these seeds cannot tell which of the two is better, so a difference the paper
    reports is neither shown nor ruled out. None where the interval excludes 0.5 (or there is
    none: fewer than 2 values a side)."""
    x, y = [v for v in x if v is not None], [v for v in y if v is not None]
    value = iqm_stats.improvement(x, y, lower_is_better=lower_is_better)
    if value["ci95"] is None or not value["ci95"][0] <= 0.5 <= value["ci95"][1]:
        return None
    seeds = f"{len(x)} seeds" if len(x) == len(y) else f"{len(x)} and {len(y)} seeds"
    return f"inconclusive at {seeds} (P(better) {iqm_stats.improvement_text(value)} includes 0.5)"


def powered_verdict(
    claim: str,
    paper: str,
    as_claimed: bool,
    shown: bool,
    reversal: str | None,
    short: str | None,
    seeds: int,
) -> str:
    """A verdict that says its power: REPRODUCED where ours ranks as the paper's `claim` says
    (`as_claimed`) and Mann-Whitney shows it against each alternative (`shown`); NOT
    reproduced where `reversal` says which alternative is significantly better, at the
    paper's budget; otherwise inconclusive: `short` (the budget below the paper's) or at
    `seeds` seeds."""
    if as_claimed and shown:
        return f"REPRODUCED ({claim}, as in the paper)"
    if reversal and not short:
        return f"NOT reproduced ({reversal})"
    undecided = short or f"inconclusive at {seeds} seeds (no difference significant)"
    if as_claimed:
        return f"{claim}, as in the paper, but not significantly: {undecided}"
    return f"{undecided} (the paper: {paper})"


def budget(record: dict) -> str:
    """A run's budget per seed as its result file states it (files from before step
    budgets give episodes only)."""
    return record.get("budget") or f"{record['episodes']:,} episodes"


def by_env(rows: list[dict]) -> dict[str, dict[str, dict]]:
    """A result's finished rows by env, then algorithm: `{env: {algo: row}}`."""
    out: dict[str, dict[str, dict]] = {}
    for r in rows:
        if r["status"] == "done":
            out.setdefault(r["env"], {})[r["algo"]] = r
    return out


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
