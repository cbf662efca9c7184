"""MuJoCo tasks through brax: sizes, obs-based termination and reward vs brax, truncation.

Every MJX compile is slow on CPU, so each (task, backend) compiles ONE random rollout that
every test of that task reads (`_rollout`, cached). Only inverted_pendulum runs in the
default suite; the other tasks are marked slow.
"""

import functools
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from envs import mujoco

pytestmark = pytest.mark.mujoco

# Documented sizes, spelled out so that a change in brax fails here.
SIZES = {  # task: (obs, action)
    "ant": (27, 8),
    "halfcheetah": (17, 6),
    "hopper": (11, 3),
    "reacher": (11, 2),
    "walker2d": (17, 6),
    "inverted_pendulum": (4, 1),
}
TERMINATES = {"hopper", "walker2d", "inverted_pendulum", "ant"}
N_ENVS, STEPS, MAX_STEPS = 16, 40, 5


def _task(name: str, slow_unless: str = "inverted_pendulum"):
    marks = () if name == slow_unless else (pytest.mark.slow,)
    return pytest.param(name, marks=marks, id=name)


ALL_TASKS = [_task(name) for name in SIZES]


@functools.cache
def _rollout(task: str, backend: str = "mjx") -> dict[str, np.ndarray]:
    """`N_ENVS` envs, `STEPS` random actions each, no reset; arrays `[N_ENVS, STEPS, ...]`."""
    env, params = envs.make(task)
    params = params.replace(backend=backend, max_steps=MAX_STEPS)
    size = env.action_spec(params).size

    def one(key):
        key, k_reset = jax.random.split(key)
        obs, state = env.reset(k_reset, params)

        def body(carry, key):
            state, obs = carry
            k_act, k_step = jax.random.split(key)
            action = jax.random.uniform(k_act, (size,), minval=-1.0, maxval=1.0)
            next_obs, state, reward, terminated, truncated, _ = env.step(
                k_step, state, action, params
            )
            out = {
                "obs": obs,
                "action": action,
                "next_obs": next_obs,
                "reward": reward,
                "terminated": terminated,
                "truncated": truncated,
                "time": state.time,
                "torso_z": state.brax.pipeline_state.x.pos[0, 2],
            }
            return (state, next_obs), out

        return jax.lax.scan(body, (state, obs), jax.random.split(key, STEPS))[1]

    out = jax.jit(jax.vmap(one))(jax.random.split(jax.random.key(0), N_ENVS))
    return jax.tree.map(np.asarray, out)


@pytest.mark.parametrize("task", ALL_TASKS)
def test_rollout_sizes_and_finite(task):
    env, params = envs.make(task)
    obs_size, action_size = SIZES[task]
    out = _rollout(task)
    assert out["obs"].shape == (N_ENVS, STEPS, obs_size)
    assert out["next_obs"].shape == (N_ENVS, STEPS, obs_size)
    assert out["obs"].dtype == np.float32 and out["reward"].dtype == np.float32
    assert out["reward"].shape == out["terminated"].shape == (N_ENVS, STEPS)
    assert out["terminated"].dtype == np.bool_ and out["truncated"].dtype == np.bool_
    assert np.isfinite(out["next_obs"]).all() and np.isfinite(out["reward"]).all()
    # The random actions moved something: envs differ from each other.
    assert out["next_obs"][:, -1].std(0).max() > 1e-3
    assert env.observation_size(params) == obs_size
    spec = env.action_spec(params)
    assert (spec.discrete, spec.size) == (False, action_size)
    assert spec.low == (-1.0,) * action_size and spec.high == (1.0,) * action_size
    assert mujoco.brax_env(task, "mjx").action_size == action_size


@pytest.mark.parametrize("task", ALL_TASKS)
def test_is_terminal_agrees_with_brax_done(task):
    env, params = envs.make(task)
    out = _rollout(task)
    terminated = out["terminated"]  # brax's own done
    np.testing.assert_array_equal(np.asarray(env.is_terminal(out["next_obs"], params)), terminated)
    assert not np.asarray(env.is_terminal(out["obs"][:, 0], params)).any()  # reset states
    if task in TERMINATES:
        assert 0.05 < terminated.mean() < 0.95
    else:
        assert not terminated.any()
    if task in ("hopper", "walker2d"):
        # brax tests the torso body's height; obs[0] must be that same number.
        np.testing.assert_array_equal(out["next_obs"][..., 0], out["torso_z"])
    if task == "ant":
        # On mjx brax's torso z lags obs[0] by one Euler substep (see envs/mujoco.py).
        obs = out["next_obs"]
        assert np.abs(obs[..., 0] - out["torso_z"]).max() > 1e-3  # the lag is real
        np.testing.assert_allclose(
            obs[..., 0] - mujoco.ANT_MJX_SUBSTEP * obs[..., 15], out["torso_z"], atol=1e-6
        )
        assert float(mujoco.brax_env("ant", "mjx").sys.opt.timestep) == pytest.approx(
            mujoco.ANT_MJX_SUBSTEP
        )


def test_is_terminal_boundaries():
    """The healthy ranges, open or closed as brax writes them, on hand-made observations."""
    params = mujoco.EnvParams(backend="generalized")  # ant: no mjx substep correction
    hopper = np.zeros((4, 11), np.float32)
    hopper[:, 0] = [0.7, 0.71, 1.2, 1.2]
    hopper[:, 1] = [0.0, 0.0, 0.2, 0.19]
    hopper[3, 5] = 100.0  # a velocity entry outside (-100, 100)
    np.testing.assert_array_equal(
        mujoco.hopper_is_terminal(hopper, params), [True, False, True, True]
    )
    walker = np.zeros((5, 17), np.float32)
    walker[:, 0] = [0.8, 0.81, 2.0, 1.99, 1.2]
    walker[:, 1] = [0.0, 0.0, 0.0, 0.0, -1.0]
    np.testing.assert_array_equal(
        mujoco.walker2d_is_terminal(walker, params), [True, False, True, False, True]
    )
    ant = np.zeros((4, 27), np.float32)
    ant[:, 0] = [0.2, 1.0, 0.19, 1.01]
    np.testing.assert_array_equal(mujoco.ant_is_terminal(ant, params), [False, False, True, True])
    rising = np.zeros((1, 27), np.float32)
    rising[0, 0], rising[0, 15] = 0.21, 2.0  # z was 0.21 - 0.01 * 2 = 0.19 one substep ago
    assert not mujoco.ant_is_terminal(rising, params)[0]
    assert mujoco.ant_is_terminal(rising, params.replace(backend="mjx"))[0]
    pendulum = np.zeros((3, 4), np.float32)
    pendulum[:, 1] = [0.2, -0.21, 0.21]
    np.testing.assert_array_equal(
        mujoco.inverted_pendulum_is_terminal(pendulum, params), [False, True, True]
    )


@pytest.mark.parametrize("task", [_task("inverted_pendulum"), _task("reacher")])
def test_exact_reward_matches_brax(task):
    env, params = envs.make(task)
    out = _rollout(task)
    reward = env.reward(out["obs"], out["action"], out["next_obs"], params)
    np.testing.assert_allclose(np.asarray(reward), out["reward"], rtol=1e-5, atol=1e-6)
    assert out["reward"].std() > 0 or task == "inverted_pendulum"


def test_reward_is_none_where_obs_does_not_fix_it():
    for task in ("ant", "halfcheetah", "hopper", "walker2d"):
        env, params = envs.make(task)
        obs_size, action_size = SIZES[task]
        obs, action = jnp.zeros((2, obs_size)), jnp.zeros((2, action_size))
        assert env.reward(obs, action, obs, params) is None


def test_truncation_exactly_at_max_steps():
    out = _rollout("inverted_pendulum")
    terminated, truncated = out["terminated"], out["truncated"]
    step = np.arange(1, STEPS + 1)
    np.testing.assert_array_equal(out["time"], np.broadcast_to(step, terminated.shape))
    np.testing.assert_array_equal(truncated, (step >= MAX_STEPS) & ~terminated)
    assert not (terminated & truncated).any()
    # Both cases occur at the limit: truncated, and terminated (which wins) at or after it.
    assert truncated[:, MAX_STEPS - 1].any()
    assert terminated[:, MAX_STEPS - 1 :].any()


@pytest.mark.slow
def test_generalized_backend_runs_and_agrees_on_termination():
    env, params = envs.make("inverted_pendulum")
    out = _rollout("inverted_pendulum", backend="generalized")
    assert np.isfinite(out["next_obs"]).all()
    assert out["terminated"].any()
    np.testing.assert_array_equal(
        np.asarray(env.is_terminal(out["next_obs"], params)), out["terminated"]
    )


def test_bad_task_or_backend_is_a_one_line_error():
    with pytest.raises(ValueError, match="unknown backend 'warp'; valid backends: mjx"):
        mujoco.brax_env("hopper", "warp")
    with pytest.raises(ValueError, match="unknown MuJoCo task 'humanoid'; valid tasks: ant"):
        mujoco.brax_env("humanoid", "mjx")


def test_brax_env_built_inside_jit_holds_no_tracers():
    mujoco.brax_env.cache_clear()
    jax.jit(lambda x: (mujoco.brax_env("inverted_pendulum", "mjx"), x)[1])(0.0)
    leaves = jax.tree.leaves(mujoco.brax_env("inverted_pendulum", "mjx").sys)
    assert leaves and not any(isinstance(leaf, jax.core.Tracer) for leaf in leaves)


def test_make_and_sizes_do_not_import_brax():
    code = (
        "import sys, envs\n"
        "env, params = envs.make('hopper')\n"
        "env.observation_size(params); env.action_spec(params)\n"
        "assert 'brax' not in sys.modules, 'brax imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
