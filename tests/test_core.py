"""Learning degree, stop draw, n-step targets, buffer and model fit: hand-checked numbers."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ldn_jax import envs
from ldn_jax.buffer import Transitions, buffer_add, buffer_init
from ldn_jax.config import FitConfig, ModelConfig
from ldn_jax.dynamics import Dynamics
from ldn_jax.learners.a2c import n_step_targets
from ldn_jax.learners.base import worker_mean
from ldn_jax.learning_degree import deviation, learning_degree, stop_draw, stop_probability


def test_learning_degree_hand_computed():
    m1 = jnp.array([1.0, 2.0, 0.0, 0.0])
    m0 = jnp.array([0.0, 0.0, 0.0, 0.0])
    sigma2 = deviation(m1, m0)  # 0.5 * mean([1, 4, 0, 0]) = 0.625
    assert float(sigma2) == pytest.approx(0.625)
    expected = 2.0 / (1.0 + np.exp(-0.625)) - 1.0
    assert float(learning_degree(sigma2)) == pytest.approx(expected, rel=1e-6)
    expected_k = 2.0 / (1.0 + np.exp(-2.0 * 0.625)) - 1.0
    assert float(learning_degree(sigma2, 2.0)) == pytest.approx(expected_k, rel=1e-6)


def test_learning_degree_zero_when_models_agree():
    dynamics = Dynamics(ModelConfig(), obs_size=4, action_size=2)
    state = dynamics.init(jax.random.key(0))
    obs = jax.random.normal(jax.random.key(1), (32, 4))
    action = jax.nn.one_hot(jnp.arange(32) % 2, 2)
    p1 = jnp.concatenate(
        [a.reshape(32, -1) for a in dynamics.predict(state.params, obs, action)], 1
    )
    p0 = jnp.concatenate(
        [a.reshape(32, -1) for a in dynamics.predict(state.frozen, obs, action)], 1
    )
    np.testing.assert_array_equal(np.asarray(learning_degree(deviation(p1, p0))), 0.0)


def test_learning_degree_monotone_and_in_range():
    # Strictly increasing wherever float32 can resolve it (K sigma2 <= 8); LD < 1 up to
    # K sigma2 ~ 17, beyond which it rounds to 1 and only the stop probability stays exact.
    sigma2 = jnp.linspace(0.0, 4.0, 401)
    for k in (0.5, 1.0, 2.0):
        ld = np.asarray(learning_degree(sigma2, k))
        assert ld[0] == 0.0
        assert (np.diff(ld) > 0).all() and (ld >= 0).all() and (ld < 1).all()
    low, high = learning_degree(1.0, 0.5), learning_degree(1.0, 2.0)
    assert float(low) < float(learning_degree(1.0, 1.0)) < float(high)
    # Tiny deviations keep their precision (2 sigmoid(x) - 1 would give 0 here).
    assert float(learning_degree(1e-8)) == pytest.approx(5e-9, rel=1e-6)


def test_stop_probability_is_one_minus_ld_without_cancellation():
    sigma2 = np.array([0.0, 1e-6, 0.3, 2.0, 20.0, 40.0])
    for k in (0.5, 1.0, 2.0):
        exact = 1.0 - (2.0 / (1.0 + np.exp(-k * sigma2)) - 1.0)
        exact[-2:] = 2.0 / (1.0 + np.exp(k * sigma2[-2:]))  # 1 - LD without cancellation
        got = np.asarray(stop_probability(jnp.asarray(sigma2, jnp.float32), k))
        np.testing.assert_allclose(got, exact, rtol=1e-5)
        assert (got > 0).all()  # imagination can always stop


@pytest.mark.parametrize("ld", [0.0, 0.2, 0.7, 0.95])
def test_stop_rate_matches_one_minus_ld(ld):
    n = 200_000
    # sigma2 with learning_degree(sigma2) == ld, through the stop probability imagination uses.
    sigma2 = jnp.full((n,), 2.0 * np.arctanh(ld), jnp.float32)
    stops = np.asarray(stop_draw(jax.random.key(3), stop_probability(sigma2)))
    p = 1.0 - ld
    bound = 5 * np.sqrt(max(p * (1 - p), 1e-12) / n)  # five binomial standard errors
    assert abs(stops.mean() - p) <= bound + 1e-6


def test_n_step_targets_hand_computed():
    gamma = 0.9
    # One worker, four steps: a truncation after step 1 (bootstrap V=10), a terminal at
    # step 3 (no bootstrap); the last step of the segment bootstraps from its next value.
    reward = jnp.array([[1.0], [2.0], [3.0], [4.0]])
    next_value = jnp.array([[5.0], [10.0], [7.0], [8.0]])
    terminated = jnp.array([[False], [False], [False], [True]])
    done = jnp.array([[False], [True], [False], [True]])
    targets = np.asarray(n_step_targets(reward, next_value, terminated, done, gamma))[:, 0]
    t1 = 2.0 + gamma * 10.0
    t0 = 1.0 + gamma * t1
    t3 = 4.0
    t2 = 3.0 + gamma * t3
    np.testing.assert_allclose(targets, [t0, t1, t2, t3], rtol=1e-6)
    # A segment cut mid-episode bootstraps its last step.
    last = n_step_targets(reward[:2], next_value[:2], terminated[:2], jnp.zeros((2, 1), bool), 0.5)
    np.testing.assert_allclose(np.asarray(last)[:, 0], [1 + 0.5 * (2 + 0.5 * 10), 2 + 0.5 * 10])


def test_worker_mean_averages_workers_and_ignores_masked_nan():
    x = jnp.array([[1.0, 10.0, jnp.nan], [3.0, jnp.nan, jnp.nan]])
    w = jnp.array([[1.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    # worker 0: mean(1, 3) = 2; worker 1: 10; worker 2 has no live step.
    assert float(worker_mean(x, w)) == pytest.approx(6.0)
    grad = jax.grad(lambda x: worker_mean(x, w))(x)
    assert np.isfinite(np.asarray(grad)).all()


def test_buffer_packs_valid_rows_and_wraps():
    buffer = buffer_init(5, obs_size=1, action_size=1)
    rows = lambda values: Transitions(
        obs=jnp.asarray(values, jnp.float32)[:, None],
        action=jnp.zeros((len(values), 1)),
        next_obs=jnp.zeros((len(values), 1)),
        reward=jnp.asarray(values, jnp.float32),
    )
    buffer = buffer_add(buffer, rows([1, 2, 3, 4]), jnp.array([True, False, True, True]))
    assert int(buffer.size) == 3 and int(buffer.cursor) == 3
    np.testing.assert_array_equal(np.asarray(buffer.data.reward), [1, 3, 4, 0, 0])
    buffer = buffer_add(buffer, rows([5, 6, 7]), jnp.array([True, True, True]))
    assert int(buffer.size) == 5 and int(buffer.cursor) == 1
    np.testing.assert_array_equal(np.asarray(buffer.data.reward), [7, 3, 4, 5, 6])


def _cartpole_transitions(key, n):
    env, params = envs.make("cartpole-v1")
    k_obs, k_act = jax.random.split(key)
    obs = jax.random.uniform(k_obs, (n, 4), minval=-0.5, maxval=0.5)
    action = jax.random.randint(k_act, (n,), 0, 2)
    state = jax.vmap(lambda o: env.reset(key, params)[1].replace(physics=o))(obs)
    next_obs, _, reward, *_ = jax.vmap(env.step, (None, 0, 0, None))(key, state, action, params)
    return Transitions(obs, jax.nn.one_hot(action, 2), next_obs, reward)


@pytest.mark.parametrize("activation", ["linear", "relu"])
def test_model_fit_lowers_held_out_mse(activation):
    model, fit = ModelConfig(activation=activation), FitConfig(updates=300)
    dynamics = Dynamics(model, obs_size=4, action_size=2, fit=fit)
    state = dynamics.init(jax.random.key(0))
    train = _cartpole_transitions(jax.random.key(1), 4096)
    held_out = _cartpole_transitions(jax.random.key(2), 1024)
    buffer = buffer_add(buffer_init(8192, 4, 2), train, jnp.ones(4096, bool))
    before = float(dynamics.loss(state.params, held_out))
    fitted, _ = jax.jit(dynamics.fit)(state, buffer, jax.random.key(3))
    after = float(dynamics.loss(fitted.params, held_out))
    assert after < 0.1 * before, (before, after)
    # M0 never moves.
    for a, b in zip(jax.tree.leaves(fitted.frozen), jax.tree.leaves(state.frozen), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.optimized
def test_an_optimized_test_compiles_with_xlas_optimisations():
    import os

    assert not jax.config.values["jax_disable_most_optimizations"]
    assert os.environ.get("JAX_DISABLE_MOST_OPTIMIZATIONS") in (None, "0")


def test_the_others_compile_without_them_where_the_session_chose_so():
    import os

    from tests.conftest import FAST

    if not os.environ.get(FAST):
        pytest.skip("the caller chose JAX_DISABLE_MOST_OPTIMIZATIONS for the whole session")
    assert jax.config.values["jax_disable_most_optimizations"]
    assert os.environ["JAX_DISABLE_MOST_OPTIMIZATIONS"] == "1"


@pytest.mark.parametrize("probabilistic", [False, True])
def test_weight_decay_adds_half_its_weight_times_the_kernels_squares(probabilistic):
    # MBPO's L2 on the model's weights (`fit.weight_decay`): kernels only, by hand
    from ldn_jax.dynamics import kernel_norm

    model = ModelConfig(probabilistic=probabilistic, ensemble=2, hidden=8, hidden_layers=2)
    plain = Dynamics(model, obs_size=4, action_size=2)
    decayed = Dynamics(model, obs_size=4, action_size=2, fit=FitConfig(weight_decay=1e-3))
    params = plain.init(jax.random.key(0)).params
    if probabilistic:  # one member
        params = jax.tree.map(lambda x: x[0], params)
    batch = _cartpole_transitions(jax.random.key(1), 64)
    leaves = jax.tree_util.tree_leaves_with_path(params)
    kernels = [x for path, x in leaves if path[-1].key == "kernel"]
    assert len(kernels) >= 2 and len(kernels) < len(leaves)  # biases (and bounds) left out
    by_hand = 0.5 * sum(float(jnp.sum(x**2)) for x in kernels)
    assert float(kernel_norm(params)) == pytest.approx(by_hand, rel=1e-6)
    gap = float(decayed.loss(params, batch)) - float(plain.loss(params, batch))
    assert gap == pytest.approx(1e-3 * by_hand, rel=1e-4)
