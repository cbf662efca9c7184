"""The bench's own arithmetic (its timings are `make bench`'s business, not the tests')."""

import numpy as np
import pytest

from bench import stages


def test_masked_share_counts_the_segments_the_longest_run_forces_on_every_run():
    # 2 runs, 3 segments of 2 steps, 2 workers. Run 0 is live for 1 segment, run 1 for 3:
    # under vmap both compute 3 segments, 2 x 3 x 2 x 2 = 24 steps, of which 2 + 8 are live.
    weight = np.zeros((2, 6, 2), np.float32)
    weight[0, :2, 0] = 1.0
    weight[1, :6, 0] = 1.0
    weight[1, :2, 1] = 1.0
    share, computed = stages._masked_share(weight, n_steps=2)
    assert computed == 24
    np.testing.assert_allclose(share, 1.0 - 10 / 24)


def test_ratios_to_ceiling_divide_real_and_real_plus_imagined_rates():
    rows = [
        {"algo": "ldn", "env_steps_per_s": 50, "imagined_steps_per_s": 25},
        {"algo": "a2c", "schedule": "steps", "env_steps_per_s": 150, "imagined_steps_per_s": 0},
    ]
    episodes, steps = stages.ratios_to_ceiling(rows, {"env_steps_per_s": 200})
    assert episodes == {
        "algo": "ldn",
        "schedule": "episodes",  # a row without one is the literal schedule's
        "real_over_ceiling": 0.25,
        "real_plus_imagined_over_ceiling": 0.375,
    }
    assert (steps["schedule"], steps["real_over_ceiling"]) == ("steps", 0.75)


def test_ppo_update_times_one_rollout_of_the_paper_presets_ppo_against_its_gradients():
    row = stages.ppo_update(seeds=1)
    assert row["rows_per_seed"] == 100 * 8  # n_steps x workers
    assert "5 epochs x 5 minibatches" in row["what"]
    assert row["learn_s"] > 0 and row["gradients_s"] > 0
    # (the seconds are rounded to 10 us in the row)
    assert row["update_only_env_steps_per_s"] == pytest.approx(800 / row["learn_s"], rel=5e-3)
    assert row["learn_over_gradients"] == pytest.approx(
        row["learn_s"] / row["gradients_s"], abs=0.01
    )


def test_seed_ratios_divide_each_algorithms_rate_by_its_rate_at_the_fewest_seeds():
    from bench import seeds

    rows = [
        {"algo": "ldn", "seeds": 100, "env_steps_per_s": 300},
        {"algo": "ldn", "seeds": 10, "env_steps_per_s": 200},
        {"algo": "ppo", "seeds": 10, "env_steps_per_s": 50},
        {"algo": "ppo", "seeds": 1000, "env_steps_per_s": 25},
    ]
    ratios = {
        (r["algo"], r["seeds"]): r["env_steps_per_s_over_fewest_seeds"]
        for r in seeds.seed_ratios(rows)
    }
    assert ratios == {("ldn", 100): 1.5, ("ldn", 10): 1.0, ("ppo", 10): 1.0, ("ppo", 1000): 0.5}
