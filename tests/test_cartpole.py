"""CartPole: parity with gymnasium, truncation, vmap and jit behaviour, registry errors."""

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from gymnasium.envs.classic_control.cartpole import CartPoleEnv

from ldn_jax import envs
from ldn_jax.envs.cartpole import THETA_THRESHOLD, X_THRESHOLD, EnvState


def _states(rng: np.random.Generator, n: int) -> np.ndarray:
    """Random states, a third of them within 1e-3 of a termination threshold."""
    states = rng.uniform([-2.4, -3, -0.21, -3], [2.4, 3, 0.21, 3], size=(n, 4))
    near = rng.random(n) < 1 / 3
    which = rng.integers(0, 2, n)  # x or theta
    sign = rng.choice([-1.0, 1.0], n)
    offset = rng.uniform(-1e-3, 1e-3, n)
    states[near & (which == 0), 0] = (sign * X_THRESHOLD + offset)[near & (which == 0)]
    states[near & (which == 1), 2] = (sign * float(THETA_THRESHOLD) + offset)[near & (which == 1)]
    return states.astype(np.float32)


@pytest.mark.parametrize("name", ["cartpole-v1", "cartpole-v2"])
def test_parity_with_gymnasium(name):
    env, params = envs.make(name)
    n_actions = len(params.forces)
    rng = np.random.default_rng(0)
    n = 10_000
    states = _states(rng, n)
    actions = rng.integers(0, n_actions, n)

    def one(physics, action):
        state = EnvState(physics=physics, time=jnp.zeros((), jnp.int32))
        obs, _, reward, terminated, truncated, _ = env.step(
            jax.random.key(0), state, action, params
        )
        return obs, reward, terminated, truncated

    obs, reward, terminated, truncated = jax.jit(jax.vmap(one))(states, actions)

    ref = CartPoleEnv()
    ref.reset(seed=0)
    ref_obs, ref_reward, ref_term = [], [], []
    for s, a in zip(states, actions, strict=True):
        force = params.forces[a]
        # gymnasium's env knows two actions; v2's five map onto its force magnitude.
        ref.force_mag = abs(force)
        ref.state = s.astype(np.float64)
        ref.steps_beyond_terminated = None
        if force == 0.0:
            ref.force_mag = 0.0
        o, r, t, _, _ = ref.step(1 if force >= 0 else 0)
        ref_obs.append(o)
        ref_reward.append(r)
        ref_term.append(t)

    np.testing.assert_allclose(np.asarray(obs), np.stack(ref_obs), rtol=1e-5, atol=1e-5)
    np.testing.assert_array_equal(np.asarray(reward), np.asarray(ref_reward, np.float32))
    np.testing.assert_array_equal(np.asarray(terminated), np.asarray(ref_term))
    assert not np.asarray(truncated).any()
    # The test must exercise both outcomes near the thresholds.
    assert 0.05 < np.mean(ref_term) < 0.95


def test_v2_actions_are_the_five_forces():
    _, params = envs.make("cartpole-v2")
    assert params.forces == (-10.0, -5.0, 0.0, 5.0, 10.0)
    for name in ("cartpole-v0", "cartpole-v1"):
        assert envs.make(name)[1].forces == (-10.0, 10.0)


def test_reset_matches_gymnasium_distribution():
    env, params = envs.make("cartpole-v1")
    obs = jax.vmap(lambda k: env.reset(k, params)[0])(jax.random.split(jax.random.key(1), 4096))
    obs = np.asarray(obs)
    assert obs.dtype == np.float32 and obs.shape == (4096, 4)
    assert (np.abs(obs) <= 0.05).all()
    # Uniform on [-0.05, 0.05]: mean 0, s.d. 0.1 / sqrt(12).
    np.testing.assert_allclose(obs.std(0), 0.1 / np.sqrt(12), rtol=0.05)
    ref_obs, _ = gym.make("CartPole-v1").reset(seed=0)
    assert ref_obs.shape == obs.shape[1:]


@pytest.mark.parametrize(
    ("name", "limit"), [("cartpole-v0", 200), ("cartpole-v1", 500), ("cartpole-v2", 1000)]
)
def test_truncation_exactly_at_max_steps(name, limit):
    env, params = envs.make(name)
    _, state = env.reset(jax.random.key(0), params)
    # Hold the pole upright so only the step limit can end the episode.
    state = state.replace(physics=jnp.zeros(4, jnp.float32))
    neutral = len(params.forces) // 2 if len(params.forces) % 2 else 0

    def body(state, _):
        upright = state.replace(physics=jnp.zeros(4, jnp.float32))
        _, state, _, terminated, truncated, _ = env.step(
            jax.random.key(0), upright, neutral, params
        )
        return state, (terminated, truncated)

    _, (terminated, truncated) = jax.lax.scan(body, state, length=limit + 3)
    terminated, truncated = np.asarray(terminated), np.asarray(truncated)
    assert not terminated.any()
    assert not truncated[: limit - 1].any()
    assert truncated[limit - 1]
    assert not (terminated & truncated).any()


def test_termination_on_last_step_is_not_truncation():
    env, params = envs.make("cartpole-v0")
    state = EnvState(
        physics=jnp.array([2.39, 1.0, 0.0, 0.0], jnp.float32),
        time=jnp.asarray(params.max_steps - 1, jnp.int32),
    )
    _, _, _, terminated, truncated, _ = env.step(jax.random.key(0), state, 1, params)
    assert bool(terminated) and not bool(truncated)


def test_is_terminal_batched_matches_step():
    env, params = envs.make("cartpole-v1")
    states = _states(np.random.default_rng(3), 2048)
    actions = np.random.default_rng(4).integers(0, 2, 2048)

    def one(physics, action):
        state = EnvState(physics=physics, time=jnp.zeros((), jnp.int32))
        obs, _, _, terminated, _, _ = env.step(jax.random.key(0), state, action, params)
        return obs, terminated

    obs, terminated = jax.vmap(one)(states, actions)
    np.testing.assert_array_equal(np.asarray(env.is_terminal(obs, params)), np.asarray(terminated))


def _rollout(env, params, key, steps=50):
    obs, state = env.reset(key, params)

    def body(carry, key):
        state, obs = carry
        k_act, k_step = jax.random.split(key)
        action = jax.random.randint(k_act, (), 0, len(params.forces))
        obs, state, reward, terminated, truncated, _ = env.step(k_step, state, action, params)
        return (state, obs), (obs, reward, terminated, truncated)

    return jax.lax.scan(body, (state, obs), jax.random.split(key, steps))[1]


@pytest.mark.optimized
def test_vmap_equals_loop_and_jit_is_finite():
    env, params = envs.make("cartpole-v2")
    keys = jax.random.split(jax.random.key(7), 1024)
    batched = jax.jit(jax.vmap(lambda k: _rollout(env, params, k)))(keys)
    single = jax.jit(lambda k: _rollout(env, params, k))
    for i in range(0, 1024, 97):
        one = single(keys[i])
        for b, o in zip(batched, one, strict=True):
            np.testing.assert_array_equal(np.asarray(b[i]), np.asarray(o))
    assert np.isfinite(np.asarray(batched[0])).all()


def test_unknown_name_error_lists_valid_names():
    with pytest.raises(ValueError, match="unknown env 'cartpole-v9'; valid names: cartpole-v0"):
        envs.make("cartpole-v9")
    with pytest.raises(ValueError) as error:
        envs.make("nope")
    assert "\n" not in str(error.value) and "cartpole-v2" in str(error.value)
