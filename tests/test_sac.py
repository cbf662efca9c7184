"""SAC's pieces (`ldn_jax.learners.sac`): the squashed Gaussian's log-density, the three losses
by hand, the Polyak step, and a one-step continuous bandit it must solve."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from ldn_jax.learners.sac import (
    SAC,
    SACConfig,
    Transitions,
    actor_loss,
    critic_loss,
    polyak,
    squashed_sample,
    temperature_loss,
)


def test_the_squashed_log_density_is_the_change_of_variables():
    mean, log_std = jnp.array([[0.3], [-1.2], [2.0]]), jnp.array([[-0.5], [0.1], [-1.0]])
    action, log_prob = squashed_sample(mean, log_std, jax.random.key(0))
    a = np.asarray(action)[:, 0].astype(float)
    u = np.arctanh(a)
    # p_a(a) = p_u(atanh a) / (1 - a^2), u ~ N(mean, std)
    expected = stats.norm.logpdf(u, np.asarray(mean)[:, 0], np.exp(np.asarray(log_std)[:, 0]))
    expected -= np.log(1 - a**2)
    np.testing.assert_allclose(np.asarray(log_prob), expected, rtol=2e-4, atol=2e-4)
    assert (np.abs(a) < 1).all()


def test_the_critic_loss_by_hand():
    batch = Transitions(
        obs=jnp.zeros((2, 1)),
        action=jnp.zeros((2, 1)),
        reward=jnp.array([1.0, 0.0]),
        next_obs=jnp.zeros((2, 1)),
        terminated=jnp.array([0.0, 1.0]),
    )
    q = jnp.array([[1.0, 2.0], [3.0, 0.0]])
    next_q = jnp.array([[2.0, 5.0], [4.0, 1.0]])  # min over critics: 2, 1
    # targets: 1 + 0.9 (2 - 0.2 x 0.5) = 2.71; the second terminated: 0
    # 1/2 (mean((1 - 2.71)^2, 2^2) + mean((3 - 2.71)^2, 0)) = 1/2 (3.46205 + 0.04205)
    loss = critic_loss(q, batch, next_q, jnp.array([0.5, 0.1]), jnp.float32(0.2), 0.9)
    assert float(loss) == pytest.approx(1.75205, rel=1e-5)


def test_the_actor_and_temperature_losses_by_hand():
    q = jnp.array([[2.0, 0.0], [1.0, 3.0]])  # min over critics: 1, 0
    assert float(actor_loss(jnp.float32(0.5), jnp.array([1.0, -1.0]), q)) == pytest.approx(-0.5)
    # log pi + target = -3, -5: entropy above the target, so alpha's gradient step shrinks it
    loss, grad = jax.value_and_grad(temperature_loss)(
        jnp.float32(0.3), jnp.array([-2.0, -4.0]), -1.0
    )
    assert float(loss) == pytest.approx(1.2) and float(grad) == pytest.approx(4.0)


def test_polyak_moves_the_target_by_tau():
    target, online = {"w": jnp.array([1.0, 2.0])}, {"w": jnp.array([3.0, 0.0])}
    moved = polyak(target, online, 0.25)
    np.testing.assert_allclose(np.asarray(moved["w"]), [1.5, 1.5])


def test_sac_solves_a_one_step_bandit():
    """Reward -(a - 0.5)^2, every step terminal: the greedy action must go to 0.5, and the
    targets must follow the critics."""
    sac = SAC(SACConfig(hidden=32, batch_size=64, lr=3e-3), obs_size=1, actions=1)
    state = sac.init(jax.random.key(0))

    def sample(key):
        action = jax.random.uniform(key, (64, 1), minval=-1.0, maxval=1.0)
        reward = -jnp.square(action[:, 0] - 0.5)
        zeros = jnp.zeros((64, 1))
        return Transitions(zeros, action, reward, zeros, jnp.ones(64))

    learn = jax.jit(lambda s, k: sac.learn(s, sample, k, 1500))
    state, metrics = learn(state, jax.random.key(1))
    greedy = float(sac.greedy(state.params, jnp.zeros((1, 1)))[0, 0])
    assert abs(greedy - 0.5) < 0.1, greedy
    assert math.isfinite(float(metrics["critic_loss"])) and float(metrics["critic_loss"]) < 0.02
    gap = jax.tree.map(lambda t, o: float(jnp.abs(t - o).max()), *(
        state.params["target"], state.params["critic"]))  # fmt: skip
    assert max(jax.tree.leaves(gap)) < 0.5
