"""Every combination of algorithm, stop rule, imagine start, LD estimator and model kind
either runs or is refused with one line: none passes validation and then fails inside the
jitted program (as `--algo ppo-ldn --stop macura` without branches once did)."""

import itertools

import jax
import jax.numpy as jnp
import pytest

from ldn_jax.config import IMAGINE_STARTS, LD_ESTIMATORS, STOP_RULES, from_preset, validate
from ldn_jax.trainer import Trainer

ALGOS = ("a2c", "a2c-model", "ldn", "ppo", "ppo-model", "ppo-ldn")
COMBINATIONS = list(
    itertools.product(ALGOS, (None, *STOP_RULES), IMAGINE_STARTS, LD_ESTIMATORS, (False, True))
)


def _config(algo, stop, start, ld, probabilistic):
    """A tiny run of the combination on CartPole; ValueError where validation refuses it."""
    model = {"imagine_start": start, "ld": ld, "probabilistic": probabilistic, "ensemble": 2}
    model |= {"hidden": 8, "branches": 4, "updates": 2} | ({"stop": stop} if stop else {})
    base = dict(env="cartpole-v1", algo=algo, seeds=1, k=(1.0,), steps=2000, schedule="steps")
    return validate(from_preset("paper", **base, model=model))


def _traces(config) -> None:
    """Trace one training iteration (no compile): what fails at trace time fails here."""
    trainer = Trainer(config)
    state = jax.eval_shape(trainer.init_batch)
    one = lambda s: trainer.iteration(jax.tree.map(lambda x: x[0, 0], s), jnp.float32(1.0))
    jax.eval_shape(one, state)


def _validated() -> dict[tuple, object]:
    found = {}
    for combination in COMBINATIONS:
        try:
            found[combination] = _config(*combination)
        except ValueError as error:
            assert "\n" not in str(error), (combination, str(error))
    return found


def test_every_combination_is_validated_or_refused_in_one_line():
    found = _validated()
    # the cross product is not all refused: every algorithm runs somewhere
    assert {combination[0] for combination in found} == set(ALGOS)
    # each (stop, start, estimator) that validates somewhere traces, once
    traced = {}
    for combination, config in found.items():
        traced.setdefault(combination[1:4], (combination, config))
    assert len(traced) > 20
    _all_trace(traced.values())


@pytest.mark.slow
def test_every_validated_combination_traces():
    _all_trace(_validated().items())


def _all_trace(combinations) -> None:
    for combination, config in combinations:
        try:
            _traces(config)
        except Exception as error:  # the failure names the combination
            pytest.fail(f"{combination} validates but fails to trace: {error}")


def test_macura_without_branches_is_refused():
    with pytest.raises(ValueError, match=r"needs imagine\.start 'real'"):
        _config("ppo-ldn", "macura", "initial", "ensemble", False)
