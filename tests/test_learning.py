"""`slow`: the algorithms learn CartPole-v1 and inverted_pendulum within stated budgets."""

import numpy as np
import pytest

from ldn_jax import load_policy
from ldn_jax.config import from_preset
from ldn_jax.host.gym_eval import episode_returns, make_env
from ldn_jax.host.run_dir import RunDir
from ldn_jax.host.training import train

# Measured on 2 CPU cores (2026-11-22), seeds 0-3, paper preset: a2c reached 150 in
# 688-1112 episodes and ldn in 839-1003; ppo in 174-253 and ppo-ldn in 240-573. The budgets
# leave room above the slowest seed.
BUDGET = {"a2c": 1600, "ldn": 1600, "ppo": 800, "ppo-ldn": 1000}


@pytest.mark.slow
@pytest.mark.parametrize("algo", list(BUDGET))
def test_reaches_150_on_cartpole_v1(algo, tmp_path):
    config = from_preset(
        "paper", env="cartpole-v1", algo=algo, seeds=4, k=(1.0,), episodes=BUDGET[algo]
    )
    summary = train(config, tmp_path, checkpoint_every=0, quiet=True)
    reached = [r for r in summary["runs"] if r["episodes_to_threshold"] is not None]
    assert len(reached) >= 3, summary["runs"]


# The fast preset on cartpole-v1 (2026-12-02 evening, AMD EPYC, 2 cores). Trained to the
# budget, the final greedy policies scored >= 475 on 9 or 10 of 10 seeds, depending on the
# last bits (late falls). Stopped where the greedy policy first scores 500 in the JAX env
# on 32 episodes (`solved_return`): 20 of 20 seeds for each algorithm, on one device and on
# two, the lowest seed 493-500 over 100 gymnasium episodes (README, "A solved CartPole").
@pytest.mark.slow
@pytest.mark.parametrize("algo", ["a2c", "ldn", "ppo"])
def test_fast_preset_solves_cartpole_v1_on_every_seed(algo, tmp_path):
    config = from_preset("fast", env="cartpole-v1", algo=algo, seeds=10)
    summary = train(config, tmp_path, checkpoint_every=0, quiet=True)
    assert all(r["solved"] is not None for r in summary["runs"]), summary["runs"]
    # In gymnasium's own CartPole-v1, as `ldn-jax eval` plays it (100 episodes, env seed 0).
    gym = [
        episode_returns(make_env("cartpole-v1"), load_policy(tmp_path, seed), 100, 0).mean()
        for seed in range(10)
    ]
    assert min(gym) >= 475, gym


# inverted_pendulum, native engine, 2 CPU cores (2026-12-01), 5 seeds, --steps 600000 (the
# default): ppo's moving return first reached 900 after 236k-259k env steps (seed 0: 252k);
# a2c's went above 900 on 4 of 5 seeds within the 600k (highest 899.8-948). One seed here.
IP_BUDGET = {"a2c": 600_000, "ppo": 500_000}


def _best_moving_return(run_dir) -> np.ndarray:
    """The highest moving return each run reached, `[K * S]`."""
    moving = RunDir(run_dir).history()["moving_after"]
    return np.nanmax(moving.reshape(moving.shape[0] * moving.shape[1], -1), axis=-1)


@pytest.mark.slow
@pytest.mark.mujoco
@pytest.mark.parametrize("algo", list(IP_BUDGET))
def test_reaches_900_on_inverted_pendulum(algo, tmp_path):
    config = from_preset(
        "paper",
        env="inverted_pendulum",
        algo=algo,
        seeds=1,
        steps=IP_BUDGET[algo],
        backend="native",
    )
    train(config, tmp_path, checkpoint_every=0, quiet=True)
    assert _best_moving_return(tmp_path)[0] >= 900


# Measured (5 seeds, native, 2 cores, 2026-12-01): the highest moving return within 300k
# env steps was 827-916 for ldn (seeds 0-1: 827, 860) and 567-853 for a2c-model (853, 774).
# The margin covers seed noise, not a known deficit.
LDN_MARGIN = 100.0


@pytest.mark.slow
@pytest.mark.mujoco
def test_ldn_is_not_worse_than_a2c_model_on_inverted_pendulum(tmp_path):
    best = {}
    for algo in ("ldn", "a2c-model"):
        config = from_preset(
            "paper", env="inverted_pendulum", algo=algo, seeds=2, k=(1.0,), steps=300_000
        )
        train(config, tmp_path / algo, checkpoint_every=0, quiet=True)
        best[algo] = _best_moving_return(tmp_path / algo).mean()
    assert best["ldn"] >= best["a2c-model"] - LDN_MARGIN, best


@pytest.mark.slow
def test_ppo_reaches_1000_on_hopper_within_300k_steps(tmp_path):
    """The default PPO on hopper (native engine), one seed: its moving return reaches 1,000
    within 300k real steps."""
    config = from_preset("paper", env="hopper", algo="ppo", seeds=1, steps=300_000)
    summary = train(config, tmp_path, checkpoint_every=0, quiet=True)
    history = RunDir(tmp_path).history()
    assert np.nanmax(history["moving_return"]) >= 1000, summary["runs"]


# sac on inverted_pendulum at 15k steps, the defaults: greedy 1,000 in gymnasium on seeds 0-4
# (exploratory) and 5-9 (confirmatory, experiments/plans/sac.md), 2026-12-06.
@pytest.mark.slow
@pytest.mark.mujoco
def test_sac_solves_inverted_pendulum_within_15k_steps(tmp_path):
    config = from_preset("paper", env="inverted_pendulum", algo="sac", seeds=2, steps=15_000)
    train(config, tmp_path, checkpoint_every=0, quiet=True)
    returns = [
        episode_returns(make_env("inverted_pendulum"), load_policy(tmp_path, seed), 10, 0).mean()
        for seed in range(2)
    ]
    assert min(returns) >= 1000, returns


# sac-ldn runs MBPO's loop end to end and learns a little on hopper within 5k steps (a smoke of
# the model-based SAC: the fit, the branches, the mixed batches), its warm-up cut to 1,000
# steps. Measured 2026-12-06 under the earlier layout (400 branches, 20 rows per real step):
# greedy 188 (a policy that falls at once scores about 20).
@pytest.mark.slow
@pytest.mark.mujoco
def test_sac_ldn_learns_on_hopper(tmp_path):
    warm = {"random_steps": 1_000, "learning_starts": 1_000}
    config = from_preset("branched", env="hopper", algo="sac-ldn", seeds=1, steps=5_000, sac=warm)
    summary = train(config, tmp_path, checkpoint_every=0, quiet=True)
    assert summary["imagined_steps"] >= 5_000 * 19  # a step at least from each start per fit
    assert summary["runs"][0]["eval_return"] > 150, summary["runs"]
