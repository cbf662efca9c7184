"""IQM, its stratified bootstrap interval and the probability of improvement, on hand-made
scores with known answers."""

import numpy as np
import pytest
from scipy.stats import mannwhitneyu

from ldn_jax.host import stats


def test_iqm_is_the_mean_of_the_middle_half():
    assert stats.iqm(np.arange(1.0, 9.0)) == 4.5  # mean of 3, 4, 5, 6
    assert stats.iqm(np.array([0.0, 1, 2, 3, 1000])) == pytest.approx(2.0)  # 1, 2, 3 kept
    # pooled over tasks
    assert stats.iqm(np.arange(10.0), np.arange(100.0, 110.0)) == pytest.approx(54.5)


def test_estimate_gives_iqm_interval_mean_and_sd():
    scores = [3.0, 1, 4, 1, 5, 9, 2, 6, 5, 3]
    out = stats.estimate(scores)
    assert out["iqm"] == pytest.approx(np.mean(sorted(scores)[2:8]))
    assert out["mean"] == pytest.approx(np.mean(scores))
    assert out["sd"] == pytest.approx(np.std(scores, ddof=1))
    assert out["n"] == 10
    low, high = out["ci95"]
    assert min(scores) <= low < out["iqm"] < high <= max(scores)
    assert stats.estimate(scores) == out  # seeded: the same interval every time


def test_degenerate_scores():
    assert stats.estimate([]) == {"iqm": None, "ci95": None, "mean": None, "sd": None, "n": 0}
    assert stats.estimate([7.0]) == {"iqm": 7.0, "ci95": None, "mean": 7.0, "sd": None, "n": 1}
    assert stats.estimate([2.0, 2.0, 2.0])["ci95"] == [2.0, 2.0]


def test_the_bootstrap_is_stratified_by_task():
    # Each resample keeps four scores of each task: the pooled IQM is then the mean of the
    # two highest of a's and the two lowest of b's, in [5, 6]. Resampling the pooled eight
    # would reach 0 (eight of a's) and 10.5.
    tasks = {"a": [0.0, 0.0, 0.0, 1.0], "b": [10.0, 10.0, 10.0, 11.0]}
    low, high = stats.estimate(tasks)["ci95"]
    assert 5.0 <= low <= high <= 6.0


def test_probability_of_improvement():
    assert stats.improvement([1.0, 2, 3], [0.0, 0, 0])["probability"] == 1.0
    assert stats.improvement([1.0, 2, 3], [1.0, 2, 3])["probability"] == 0.5
    assert stats.improvement([1.0, 2], [3.0, 4])["probability"] == 0.0
    assert stats.improvement([1.0, 2], [3.0, 4], lower_is_better=True)["probability"] == 1.0
    rng = np.random.default_rng(3)
    x, y = rng.normal(0, 1, 10), rng.normal(0.5, 1, 12)
    out = stats.improvement(x, y)
    assert out["probability"] == pytest.approx(mannwhitneyu(x, y).statistic / (10 * 12))
    low, high = out["ci95"]
    assert 0 <= low < out["probability"] < high <= 1
    # over two tasks: the mean of the two tasks' probabilities
    both = stats.improvement({"a": [1.0, 2], "b": [0.0, 0]}, {"a": [0.0, 0], "b": [1.0, 2]})
    assert both["probability"] == 0.5
    with pytest.raises(ValueError, match="same tasks"):
        stats.improvement({"a": [1.0]}, [1.0])


def test_cells():
    assert stats.text({"iqm": 512.3, "ci95": [480.0, 540.9]}) == "512 [480, 541]"
    assert stats.text({"iqm": None, "ci95": None}) == "–"
    assert stats.improvement_text({"probability": 0.8, "ci95": [0.61, 0.97]}) == (
        "0.80 [0.61, 0.97]"
    )


def test_holm_adjusts_step_down_in_the_given_order():
    # sorted: 0.01 x 4 = 0.04, 0.02 x 3 = 0.06, 0.03 x 2 = 0.06 (kept monotone), 0.5 x 1
    assert stats.holm([0.03, 0.5, 0.01, 0.02]) == pytest.approx([0.06, 0.5, 0.04, 0.06])
    # a later step never lowers an earlier one; adjusted p is capped at 1
    assert stats.holm([0.04, 0.045]) == pytest.approx([0.08, 0.08])
    assert stats.holm([0.6, 0.7]) == pytest.approx([1.0, 1.0])
    assert stats.holm([0.014] + [0.5] * 11)[0] == pytest.approx(0.168)
