"""The readings of eq. 3 as configuration: the reduction over outputs, the window of B steps
and the scale kept apart from K, on hand-computed numbers."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ldn_jax.config import AgentConfig, ModelConfig, StopConfig, from_preset, validate
from ldn_jax.dynamics import Dynamics
from ldn_jax.imagination import EnvFacts, _joined, ld_history, model_world, stop_rule
from ldn_jax.learners.a2c import A2C
from ldn_jax.learning_degree import deviation, disagreement, learning_degree, windowed
from ldn_jax.rollout import Player, play_episodes

M1 = jnp.array([1.0, 2.0, 0.0, 0.0, 1.0])
M0 = jnp.zeros(5)


def test_each_reduction_hand_computed():
    assert float(deviation(M1, M0, "mean")) == pytest.approx(0.5 * 6 / 5)  # 0.6
    assert float(deviation(M1, M0, "sum")) == pytest.approx(0.5 * 6)  # 3.0
    # LD = tanh(K sigma2 / 2): the sum reading is D = 5 times the mean one before the tanh
    assert float(learning_degree(deviation(M1, M0, "sum"))) == pytest.approx(np.tanh(1.5))
    members = jnp.stack([M1, M0])  # variance over two members: (M1 / 2)^2
    assert float(disagreement(members, "sum")) == pytest.approx(0.5 * 6 / 4)
    assert float(disagreement(members, "mean")) == pytest.approx(0.5 * 6 / 20)


def test_a_window_sums_the_steps_taken_so_far():
    history = jnp.zeros((2,))  # B = 3
    totals = []
    for value in (1.0, 2.0, 3.0, 4.0):
        total, history = windowed(jnp.float32(value), history)
        totals.append(float(total))
    assert totals == [1.0, 3.0, 6.0, 9.0]  # at the start only the steps so far
    assert windowed(jnp.float32(5.0), None) == (5.0, None)  # B = 1: the step's own


def test_readings_are_settings_and_paper_fig5_is_a_preset():
    paper = from_preset("paper")
    assert (paper.model.ld_reduce, paper.model.ld_window, paper.model.ld_scale) == (
        "mean",
        1,
        1.0,
    )
    fig5 = from_preset("paper-fig5")
    assert (fig5.model.ld_reduce, fig5.model.ld_window, fig5.model.ld_scale) == ("sum", 1, 10.0)
    assert fig5.agent == paper.agent and fig5.k == paper.k  # K keeps its meaning
    for bad, needle in (
        ({"ld_reduce": "max"}, "unknown ld_reduce 'max'"),
        ({"ld_window": 0}, "ld_window must be >= 1"),
        ({"ld_scale": 0.0}, "ld_scale must be > 0"),
    ):
        with pytest.raises(ValueError, match=needle):
            validate(from_preset("paper", model=bad))


def test_imagined_steps_read_the_configured_deviation(reduce="sum", window=3, scale=2.0):
    """Each imagined step's LD is tanh(K s / 2) of s = scale x the reduced deviation summed
    over the episode's last `window` steps, recomputed here from M1 and M0 on the steps
    the world took (the literal reading, mean and no window, is every other test's)."""
    config = ModelConfig(ld_reduce=reduce, ld_window=window, ld_scale=scale)
    dynamics = Dynamics(config, obs_size=4, action_size=2)
    model = dynamics.init(jax.random.key(0))
    model = model.replace(params=jax.tree.map(lambda p: p + 0.05, model.params))
    learner = A2C(AgentConfig(), obs_size=4, action_spec=2)
    encode = lambda a: jax.nn.one_hot(a, 2)
    never = lambda obs: jnp.zeros(obs.shape[:-1], bool)
    gain = jnp.float32(0.5)
    world = model_world(
        dynamics, model, EnvFacts(never, encode), gain, stop_rule(StopConfig(), "none")
    )
    obs = jax.random.uniform(jax.random.key(2), (3, 4), minval=-0.05, maxval=0.05)
    _, episodes = jax.jit(play_episodes, static_argnums=2)(
        jax.random.key(3), learner.init(jax.random.key(4)), Player(learner, world, 12), obs,
        ld_history(dynamics, 3),
    )  # fmt: skip
    steps = episodes.steps
    action = encode(steps.action)
    m1 = _joined(*dynamics.predict_normalized(model.params, model.stats, steps.obs, action))
    m0 = _joined(*dynamics.predict_normalized(model.frozen, model.stats, steps.obs, action))
    sigma2 = scale * np.asarray(deviation(m1, m0, reduce))[:12]  # [T, W]
    summed = np.stack([sigma2[max(0, t - window + 1) : t + 1].sum(0) for t in range(12)])
    expected = np.tanh(0.5 * 0.5 * summed)
    np.testing.assert_allclose(np.asarray(episodes.extras["ld"])[:12], expected, rtol=2e-5)
    assert (expected > 0).all()
