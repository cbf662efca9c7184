"""The ensemble learning degree: disagreement, its scale, LD and the stop probability."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ldn_jax.learning_degree import (
    ERROR_FLOOR,
    disagreement,
    ensemble_learning_degree,
    ensemble_mean,
    ensemble_stop_probability,
    relative_disagreement,
)

# -- (a) the estimator's maths ---------------------------------------------------------------


def test_ensemble_learning_degree_hand_computed():
    # Two members, two outputs: mean [1, 1], variance [1, 1] -> d = 1/2 mean([1, 1]) = 0.5.
    members = jnp.array([[0.0, 0.0], [2.0, 2.0]])
    d = disagreement(members)
    assert float(d) == 0.5
    np.testing.assert_array_equal(np.asarray(ensemble_mean(members)), [1.0, 1.0])
    d_rel = relative_disagreement(d, 0.25)  # in units of the fit MSE: 2
    assert float(d_rel) == 2.0
    assert float(ensemble_learning_degree(d_rel)) == pytest.approx(2 / (1 + np.exp(2)), rel=1e-6)
    assert float(ensemble_stop_probability(d_rel)) == pytest.approx(np.tanh(1.0), rel=1e-6)
    # Agreement: LD exactly 1, P(stop) exactly 0; a zero error scale is floored, not divided by.
    assert (
        float(ensemble_learning_degree(0.0)) == 1.0 and float(ensemble_stop_probability(0.0)) == 0
    )
    assert float(relative_disagreement(1e-12, 0.0)) == pytest.approx(1e-12 / ERROR_FLOOR)
    # Large disagreement: LD -> 0, P(stop) -> 1.
    assert float(ensemble_learning_degree(50.0)) < 1e-20
    assert float(ensemble_stop_probability(50.0)) == 1.0


def test_ensemble_ld_monotone_in_k_and_stop_is_one_minus_ld_without_cancellation():
    d_rel = jnp.linspace(0.01, 8.0, 200)
    lds = [np.asarray(ensemble_learning_degree(d_rel, k)) for k in (0.5, 1.0, 2.0)]
    assert (lds[0] > lds[1]).all() and (lds[1] > lds[2]).all()  # larger K, stops sooner
    assert all((np.diff(ld) < 0).all() for ld in lds)  # falls as members disagree
    for k, ld in zip((0.5, 1.0, 2.0), lds, strict=True):
        np.testing.assert_allclose(np.asarray(ensemble_stop_probability(d_rel, k)), 1 - ld, 1e-5)
    # 1 - 2 sigmoid(-x) rounds to 0 here; tanh keeps it.
    assert float(ensemble_stop_probability(1e-8)) == pytest.approx(5e-9, rel=1e-6)


def test_disagreement_is_exactly_zero_for_equal_members():
    # A plain mean of 3 or 5 equal float32 values need not round back to them: np.var of the
    # stack would be tiny but nonzero for many of these.
    x = jax.random.normal(jax.random.key(0), (1000, 5)) * 1e3
    for members in (3, 5):
        stack = jnp.broadcast_to(x, (members, *x.shape))
        np.testing.assert_array_equal(np.asarray(disagreement(stack)), 0.0)
        np.testing.assert_array_equal(np.asarray(ensemble_mean(stack)), np.asarray(x))
