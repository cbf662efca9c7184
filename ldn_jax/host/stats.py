"""The statistics runs are reported with: the interquartile mean (IQM) with a stratified
bootstrap 95% interval, and the probability of improvement (Agarwal et al., NeurIPS 2021,
"Deep RL at the edge of the statistical precipice"; the `rliable` library).

scipy's bootstrap, not rliable: rliable pulls in arch, statsmodels, pandas and seaborn for
the same few lines. The estimates are rliable's: IQM = `scipy.stats.trim_mean(x, 0.25)`
over all scores, percentile intervals from resamples drawn within each task on its own
(the stratified bootstrap: scipy resamples each of several samples independently), and the
probability of improvement P(X > Y) + P(X = Y) / 2 averaged over tasks, which is the
Mann-Whitney U statistic over n m.

    estimate([0.1, 0.4, 0.5, 0.9])       -> {"iqm": ..., "ci95": [lo, hi], "mean": ..., ...}
    estimate({"v0": a, "v1": b})          -> the same over two tasks (stratified)
    improvement(x, y, lower_is_better=True)

Every interval is seeded (`SEED`), so a report regenerated from the same runs is the same.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

RESAMPLES = 2000
"""Bootstrap resamples per interval (rliable's default: 2,000)."""

SEED = 0
"""The bootstrap's random seed."""

CONFIDENCE = 0.95

Scores = Sequence[float] | np.ndarray | Mapping[str, Sequence[float] | np.ndarray]
"""One task's scores (one per seed), or several tasks' by name (stratified)."""


def iqm(*tasks: np.ndarray, axis: int = -1) -> np.ndarray | float:
    """The interquartile mean of all the scores of `tasks` pooled: the mean of the middle
    half (`scipy.stats.trim_mean` cutting 25% at each end, as rliable does)."""
    from scipy import stats  # here, not at import: scipy.stats takes most of a second

    return stats.trim_mean(np.concatenate(tasks, axis=axis), 0.25, axis=axis)


def _tasks(scores: Scores) -> list[np.ndarray]:
    groups = scores.values() if isinstance(scores, Mapping) else [scores]
    return [np.asarray(g, float) for g in groups]


def interval(scores: Scores, statistic=iqm) -> list[float] | None:
    """The stratified bootstrap 95% percentile interval of `statistic` (a function of the
    tasks' score arrays along `axis`); None with fewer than two scores in some task, where
    there is nothing to resample."""
    tasks = _tasks(scores)
    if any(t.size < 2 for t in tasks):
        return None
    if all(np.all(t == t[0]) for t in tasks):  # nothing varies: the interval is the point
        point = float(statistic(*tasks, axis=-1))
        return [point, point]
    from scipy import stats

    result = stats.bootstrap(
        tasks,
        statistic,
        n_resamples=RESAMPLES,
        confidence_level=CONFIDENCE,
        method="percentile",
        paired=False,
        vectorized=True,
        rng=np.random.default_rng(SEED),
    )
    return [float(result.confidence_interval.low), float(result.confidence_interval.high)]


def estimate(scores: Scores) -> dict:
    """IQM with its interval, and mean and s.d. (ddof 1) as the paper's tables give them,
    over all scores; `n` counts them. Empty scores give Nones."""
    tasks = [t for t in _tasks(scores) if t.size]
    pooled = np.concatenate(tasks) if tasks else np.zeros(0)
    if pooled.size == 0:
        return {"iqm": None, "ci95": None, "mean": None, "sd": None, "n": 0}
    return {
        "iqm": float(iqm(*tasks)),
        "ci95": interval(dict(enumerate(tasks))),
        "mean": float(pooled.mean()),
        "sd": float(pooled.std(ddof=1)) if pooled.size > 1 else None,
        "n": int(pooled.size),
    }


def _improvement(*samples: np.ndarray, axis: int = -1, lower_is_better: bool = False):
    """P(X > Y) + P(X = Y) / 2 averaged over tasks; `samples` = x_1, y_1, x_2, y_2, ..."""
    values = []
    for x, y in zip(samples[::2], samples[1::2], strict=True):
        x, y = np.moveaxis(x, axis, -1), np.moveaxis(y, axis, -1)
        if lower_is_better:
            x, y = -x, -y
        diff = x[..., :, None] - y[..., None, :]
        values.append(np.mean((diff > 0) + 0.5 * (diff == 0), axis=(-2, -1)))
    return np.mean(values, axis=0)


def improvement(x: Scores, y: Scores, lower_is_better: bool = False) -> dict:
    """The probability that a run of X beats a run of Y (rliable's probability of
    improvement; its point value is U / (n m) of the Mann-Whitney test), averaged over
    tasks, with its stratified bootstrap 95% interval. `x` and `y` name the same tasks;
    `lower_is_better` for episodes or steps to threshold."""
    xs, ys = _tasks(x), _tasks(y)
    if isinstance(x, Mapping) != isinstance(y, Mapping) or len(xs) != len(ys):
        raise ValueError("improvement needs the same tasks on both sides")
    pairs = [a for pair in zip(xs, ys, strict=True) for a in pair]
    if any(s.size == 0 for s in pairs):
        return {"probability": None, "ci95": None}
    statistic = lambda *samples, axis=-1: _improvement(
        *samples, axis=axis, lower_is_better=lower_is_better
    )
    point = float(statistic(*pairs))
    low_high = None
    if all(s.size >= 2 for s in pairs):
        if all(np.all(s == s[0]) for s in pairs):
            low_high = [point, point]
        else:
            from scipy import stats

            result = stats.bootstrap(
                pairs,
                statistic,
                n_resamples=RESAMPLES,
                confidence_level=CONFIDENCE,
                method="percentile",
                paired=False,
                vectorized=True,
                rng=np.random.default_rng(SEED),
            )
            ci = result.confidence_interval
            low_high = [float(ci.low), float(ci.high)]
    return {"probability": point, "ci95": low_high}


def holm(pvalues: Sequence[float]) -> list[float]:
    """Holm's step-down adjusted p values (Holm 1979), in the order given: the i-th smallest
    p times (m - i + 1), made non-decreasing along that order and capped at 1. A comparison
    is significant at family-wise level alpha where its adjusted p is below alpha."""
    p = np.asarray(pvalues, float)
    order = np.argsort(p, kind="stable")
    scaled = p[order] * (len(p) - np.arange(len(p)))
    adjusted = np.minimum(np.maximum.accumulate(scaled), 1.0)
    out = np.empty_like(adjusted)
    out[order] = adjusted
    return out.tolist()


def planned_tests(
    scores: dict[tuple[str, str], Sequence[float]],
    groups: Sequence[str],
    comparisons: Sequence[tuple[str, str]],
    alpha: float = 0.05,
    group: str = "env",
) -> list[dict] | None:
    """A plan's one-sided comparisons "a > b" in each group (task), `scores[group, arm]`:
    Mann-Whitney U (`alternative="greater"`), P(improvement) with its interval, and Holm's
    correction over all of them (`shown` where the adjusted p is below `alpha`). None until
    every comparison can be made. Each test is keyed by `group`'s name."""
    from scipy import stats

    out = []
    for name in groups:
        for a, b in comparisons:
            if (name, a) not in scores or (name, b) not in scores:
                return None
            x, y = scores[name, a], scores[name, b]
            p = float(stats.mannwhitneyu(x, y, alternative="greater").pvalue)
            out.append({group: name, "a": a, "b": b, "p": p, **improvement(x, y)})
    for test, adjusted in zip(out, holm([t["p"] for t in out]), strict=True):
        test["holm_p"] = adjusted
        test["shown"] = adjusted < alpha
    return out


def tests_table(
    found: Sequence[dict], group: str, probability: str, verdicts: tuple[str, str]
) -> list[str]:
    """`planned_tests`' result as a markdown table: a row per test, `group` its first column,
    `probability` the heading of P(improvement)'s, `verdicts` (shown, not shown) the last."""
    lines = [
        f"| {group} | comparison | {probability} | p | Holm p | verdict |",
        "|---|---|---|---|---|---|",
    ]
    for t in found:
        lines.append(
            f"| {t[group]} | `{t['a']}` > `{t['b']}` | {improvement_text(t)} | "
            f"{t['p']:.3g} | {t['holm_p']:.3g} | {verdicts[0] if t['shown'] else verdicts[1]} |"
        )
    return lines


def text(value: dict, digits: int = 0) -> str:
    """`estimate`'s result as a table cell: `512 [480, 540]` (IQM [95% interval])."""
    if value["iqm"] is None:
        return "–"
    point = f"{value['iqm']:,.{digits}f}"
    if value["ci95"] is None:
        return point
    low, high = value["ci95"]
    return f"{point} [{low:,.{digits}f}, {high:,.{digits}f}]"


def improvement_text(value: dict) -> str:
    """`improvement`'s result as text: `0.82 [0.61, 0.97]`."""
    if value["probability"] is None:
        return "–"
    if value["ci95"] is None:
        return f"{value['probability']:.2f}"
    low, high = value["ci95"]
    return f"{value['probability']:.2f} [{low:.2f}, {high:.2f}]"
