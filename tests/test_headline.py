"""The confirmatory batch (`experiments.paper.headline`): its arms are the plan's, and its
verdicts wait for the whole family and apply Holm's correction."""

import pytest

from experiments.paper import headline


def test_the_arms_are_the_plans():
    configs = {
        (env, arm): headline.config_of(env, arm, 10, 10, 200_000)
        for env in headline.ENVS
        for arm in headline.ARMS
    }
    for config in configs.values():
        assert (config.seeds, config.first_seed, config.steps) == (10, 10, 200_000)
        assert config.preset == "branched" and config.k == (1.0,)
    for env, epochs in (("halfcheetah", 20), ("hopper", 10)):
        assert configs[env, "ppo"].ppo.epochs == epochs
        assert configs[env, "ppo-steps"].ppo.epochs == 2 * epochs
        assert configs[env, "ppo-steps"].model == configs[env, "ppo"].model
        cap = configs[env, "ppo-ldn"].imagine.cut
        assert cap == {"halfcheetah": 15, "hopper": 5}[env]
        assert configs[env, "ppo-model"].stop_rule == "none"
        assert configs[env, "ppo-model"].imagine.cut == cap
        assert configs[env, "ppo-ldn"].model.ld == "ensemble"
        m0 = configs[env, "ppo-ldn-m0"]
        assert m0.model.ld == "m0" and m0.stop_rule == "ld" and m0.model.probabilistic
        # the two LD arms differ in the estimator only
        assert m0.model.__class__(**{**vars(m0.model), "ld": "ensemble"}) == (
            configs[env, "ppo-ldn"].model
        )


def _rows(missing: str | None = None) -> list[dict]:
    scores = {
        "ppo": [1.0, 2, 3, 4, 5, 6, 7, 8, 9, 10],
        "ppo-steps": [1.5, 2, 3, 4, 5, 6, 7, 8, 9, 10],
        "ppo-model": [21.0, 22, 23, 24, 25, 26, 27, 28, 29, 30],
        "ppo-ldn": [21.5, 22, 23, 24, 25, 26, 27, 28, 29, 30],
        "ppo-ldn-m0": [5.0, 6, 7, 8, 9, 10, 11, 12, 13, 14],
    }
    return [
        {"env": env, "arm": arm, "scores": values}
        for env in headline.ENVS
        for arm, values in scores.items()
        if (env, arm) != (headline.ENVS[1], missing)
    ]


def test_tests_wait_for_the_family_and_are_holm_corrected():
    assert headline.tests(_rows(missing="ppo-steps")) is None
    found = headline.tests(_rows())
    assert len(found) == 16
    by = {(t["env"], t["a"], t["b"]): t for t in found}
    # every model arm seed above every PPO seed: U = 100; eight comparisons share that p,
    # so Holm multiplies it by 16 (the step-down keeps the later ones at the first's value)
    beat = by["hopper", "ppo-model", "ppo"]
    assert beat["probability"] == 1.0 and beat["p"] < 1e-3
    assert beat["shown"] and beat["holm_p"] == pytest.approx(16 * beat["p"], rel=1e-3)
    # nearly equal samples: not shown, however the raw p falls
    assert not by["hopper", "ppo-ldn", "ppo-model"]["shown"]
    assert all(t["holm_p"] >= t["p"] for t in found)
    text = headline.section([], found)
    assert "Holm's correction over all 16" in text and "A beats B" in text
