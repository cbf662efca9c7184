"""Budgets: `--steps` (real env steps per seed and K) stops each run at the first iteration
that reaches it, and summary.json's counts are metrics.jsonl's."""

import dataclasses
import json

import pytest

from ldn_jax.config import from_preset
from ldn_jax.host.training import train

STEPS = 3000


@pytest.fixture(scope="module")
def budget_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("steps")
    config = from_preset(
        "paper", env="cartpole-v0", algo="ldn", seeds=2, k=(0.5, 2.0), steps=STEPS, workers=4
    )
    config = dataclasses.replace(config, chunk_iterations=2)
    summary = train(config, out, checkpoint_every=0, quiet=True)
    lines = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    return config, summary, lines


def test_each_run_stops_at_the_first_iteration_that_reaches_the_budget(budget_run):
    _, _, lines = budget_run
    runs = {(line["k"], line["seed"]) for line in lines}
    assert len(runs) == 4
    reached_at = {}
    for run in runs:
        mine = [line for line in lines if (line["k"], line["seed"]) == run]
        mine.sort(key=lambda line: line["iteration"])
        first = next(i for i, line in enumerate(mine) if line["env_steps"] >= STEPS)
        assert first == 0 or mine[first - 1]["env_steps"] < STEPS
        after = mine[first:]  # the run is stopped: nothing moves any more
        assert {(line["env_steps"], line["episodes"]) for line in after} == {
            (mine[first]["env_steps"], mine[first]["episodes"])
        }
        reached_at[run] = mine[first]["iteration"]
    # The batch stops with the chunk in which its last run reached the budget.
    last = max(reached_at.values())
    assert max(line["iteration"] for line in lines) == -(-last // 2) * 2


def test_summary_counts_are_the_metrics_sums(budget_run):
    _, summary, lines = budget_run
    final = {}
    for line in lines:
        final[(line["k"], line["seed"])] = line
    assert summary["budget"] == {"steps": STEPS}
    assert summary["env_steps"] == sum(line["env_steps"] for line in final.values())
    assert summary["real_episodes"] == sum(line["episodes"] for line in final.values())
    assert summary["eval_seconds"] >= 0 and summary["eval_share"] >= 0


def test_an_episodes_run_records_its_budget_and_both_counts(tmp_path):
    config = from_preset("paper", env="cartpole-v0", algo="a2c", seeds=2, episodes=8, workers=4)
    summary = train(config, tmp_path, checkpoint_every=0, quiet=True)
    assert summary["budget"] == {"episodes": 8}
    # Whole chunks: 5 iterations of 4 workers for each of the 2 seeds.
    assert summary["real_episodes"] == 2 * config.iterations * config.workers == 40
    assert summary["env_steps"] > 0
