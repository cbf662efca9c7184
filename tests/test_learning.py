"""`slow`: the algorithms learn CartPole-v1 within a stated budget (paper preset)."""

import pytest

from experiments.run import train
from ldn_jax.config import from_preset

# Measured on 2 CPU cores (2026-11-22), seeds 0-3, paper preset: a2c reached 150 in
# 688-1112 episodes and ldn in 839-1003; ppo in 174-253 and ppo-ldn in 240-573. The budgets
# leave room above the slowest seed.
BUDGET = {"a2c": 1600, "ldn": 1600, "ppo": 800, "ppo-ldn": 1000}


@pytest.mark.slow
@pytest.mark.parametrize("algo", list(BUDGET))
def test_reaches_150_on_cartpole_v1(algo, tmp_path):
    config = from_preset("paper", env="cartpole-v1", algo=algo, seeds=4, episodes=BUDGET[algo])
    summary = train(config, tmp_path, checkpoint_every=0, quiet=True)
    reached = [r for r in summary["runs"] if r["episodes_to_threshold"] is not None]
    assert len(reached) >= 3, summary["runs"]
