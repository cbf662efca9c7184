"""MuJoCo tasks: gymnasium parity of the native engine, batching, sizes, termination, rewards,
truncation, errors, the mjx engine, and a native training run that resumes to the bit.

The native engine compiles in about a second, so its tests run in the default suite; MJX
compiles slowly on CPU, so only inverted_pendulum compiles an MJX program by default.
"""

import dataclasses
import functools
import subprocess
import sys

import gymnasium
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from ldn_jax import envs
from ldn_jax.envs.mujoco import TASKS, EnvState, control, model, native

pytestmark = pytest.mark.mujoco

# Documented sizes, spelled out so that a change in a definition fails here.
SIZES = {  # task: (obs, action)
    "ant": (105, 8),
    "ant-nocfrc": (27, 8),
    "halfcheetah": (17, 6),
    "hopper": (11, 3),
    "reacher": (10, 2),
    "walker2d": (17, 6),
    "inverted_pendulum": (4, 1),
}
FULL = mujoco.mjtState.mjSTATE_FULLPHYSICS
PARITY_STEPS = 200


def _params(task: str, backend: str = "native", max_steps: int = 1000):
    env, params = envs.make(task)
    return env, params.replace(backend=backend, max_steps=max_steps)


def _grid_actions(rng: np.random.Generator, steps: int, size: int) -> np.ndarray:
    """Random actions on a grid of 1/512: their controls (x3 for the pendulum) are exact in
    float32 however XLA arranges the affine map, so both sides apply the very same control."""
    return (rng.integers(-512, 513, (steps, size)) / 512).astype(np.float32)


def _gym_state(g) -> np.ndarray:
    state = np.zeros(mujoco.mj_stateSize(g.unwrapped.model, FULL))
    mujoco.mj_getState(g.unwrapped.model, g.unwrapped.data, state, FULL)
    return state


# -- parity with gymnasium -------------------------------------------------------------------


@functools.cache
def _parity(task: str) -> dict:
    """gymnasium's env and ours from gymnasium's reset state, the same 200 actions.

    gymnasium's solver warm start is cleared before each step: `mujoco.rollout` starts each
    env step cold (see ldn_jax/envs/mujoco/native.py), and halfcheetah and ant turn any difference
    of 1e-13 into O(1) within 200 steps. Both envs step past termination (gymnasium's
    unwrapped env does not stop), and both truncate at 200 steps."""
    t = TASKS[task]
    env, params = _params(task, max_steps=PARITY_STEPS)
    with model.settotalmass_ignored():
        g = gymnasium.make(
            t.gymnasium_id, max_episode_steps=PARITY_STEPS, **dict(t.gymnasium_kwargs)
        )
    gym_obs, _ = g.reset(seed=3)
    engine = native.engine(t)
    bits = engine.from_state(_gym_state(g))
    qpos, qvel = g.unwrapped.data.qpos, g.unwrapped.data.qvel
    _, physics = engine.reset(jnp.asarray(qpos, jnp.float32), jnp.asarray(qvel, jnp.float32))
    state = EnvState(engine=bits, physics=physics, time=jnp.zeros((), jnp.int32))
    step = jax.jit(lambda s, a: env.step(None, s, a, params))
    actions = _grid_actions(np.random.default_rng(0), PARITY_STEPS, t.action_size)
    rows = {k: [] for k in ("obs", "reward", "terminated", "truncated")}
    gym = {k: [] for k in rows}
    states = []
    for action in actions:
        obs, state, reward, terminated, truncated, _ = step(state, jnp.asarray(action))
        g.unwrapped.data.qacc_warmstart[:] = 0.0
        ctrl = np.asarray(control(t, jnp.asarray(action)), np.float64)
        out = g.step(ctrl)
        for name, ours, theirs in zip(
            rows, (obs, reward, terminated, truncated), out[:4], strict=True
        ):
            rows[name].append(np.asarray(ours))
            gym[name].append(np.asarray(theirs))
        states.append((engine.full_state(state.engine), _gym_state(g)))
    return {
        "ours": {k: np.stack(v) for k, v in rows.items()},
        "gym": {k: np.stack(v) for k, v in gym.items()},
        "reset_obs": (np.asarray(env.reset(jax.random.key(0), params)[0]), gym_obs),
        "states": states,
    }


@pytest.mark.parametrize("task", list(SIZES))
def test_native_matches_gymnasium_for_200_steps(task):
    """Same C engine, model and frame skip: the float64 physics state equals gymnasium's to the
    bit at every step. Observations and rewards are computed in float32 from it, so they agree
    to float32 rounding: obs within 1e-6 relative to the largest entry, rewards within 1e-4
    (forward velocity is (x' - x) / dt of float32 positions: x up to about 10 m has a rounding
    of 1e-6, over dt = 0.008 s for hopper/walker2d)."""
    out = _parity(task)
    ours, gym = out["ours"], out["gym"]
    for mine, theirs in out["states"]:
        np.testing.assert_array_equal(mine, theirs)
    scale = np.maximum(1.0, np.abs(gym["obs"]).max(axis=1, keepdims=True))
    np.testing.assert_array_less(np.abs(ours["obs"] - gym["obs"]) / scale, 1e-6)
    np.testing.assert_allclose(ours["reward"], gym["reward"], atol=1e-4, rtol=1e-6)
    np.testing.assert_array_equal(ours["terminated"], gym["terminated"])
    # gymnasium's TimeLimit may report both flags; ours never does (terminated wins).
    np.testing.assert_array_equal(ours["truncated"], gym["truncated"] & ~gym["terminated"])
    assert ours["truncated"][-1] or ours["terminated"][-1]
    if task in ("hopper", "walker2d", "ant", "ant-nocfrc", "inverted_pendulum"):
        assert gym["terminated"].any()  # random actions do reach the termination test
    assert np.abs(np.diff(gym["obs"], axis=0)).max() > 1e-2  # the envs did move


@pytest.mark.parametrize("task", list(SIZES))
def test_sizes_and_control_ranges_match_the_models(task):
    env, params = _params(task)
    obs_size, action_size = SIZES[task]
    m = model.load(TASKS[task].asset)
    assert env.observation_size(params) == obs_size
    spec = env.action_spec(params)
    assert (spec.discrete, spec.size) == (False, action_size) == (False, m.nu)
    assert spec.low == (-1.0,) * action_size and spec.high == (1.0,) * action_size
    np.testing.assert_array_equal(m.actuator_ctrlrange, [TASKS[task].ctrl_range] * m.nu)
    obs, _ = env.reset(jax.random.key(0), params)
    assert obs.shape == (obs_size,) and obs.dtype == jnp.float32
    with model.settotalmass_ignored():
        g = gymnasium.make(TASKS[task].gymnasium_id, **dict(TASKS[task].gymnasium_kwargs))
    assert g.observation_space.shape == (obs_size,)


# -- batching ----------------------------------------------------------------------------------


def _rollout(task: str, backend: str, batch: tuple[int, ...], steps: int, max_steps: int = 1000):
    """`steps` random actions on a `batch` of envs (nested vmaps), arrays `[*batch, steps, ...]`."""
    env, params = _params(task, backend, max_steps)
    size = env.action_spec(params).size

    def one(key):
        k_reset, k_act = jax.random.split(key)
        obs, state = env.reset(k_reset, params)

        def body(carry, key):
            state, obs = carry
            action = jax.random.uniform(key, (size,), minval=-1.0, maxval=1.0)
            next_obs, state, reward, terminated, truncated, _ = env.step(key, state, action, params)
            out = dict(obs=obs, action=action, next_obs=next_obs, reward=reward)
            out.update(terminated=terminated, truncated=truncated, time=state.time)
            return (state, next_obs), out

        return jax.lax.scan(body, (state, obs), jax.random.split(k_act, steps))[1]

    fn = one
    for _ in batch:
        fn = jax.vmap(fn)
    keys = jax.random.split(jax.random.key(0), int(np.prod(batch))).reshape(batch)
    return jax.tree.map(np.asarray, jax.jit(fn)(keys))


@pytest.mark.parametrize("task", ["halfcheetah", "inverted_pendulum"])
def test_native_reset_and_vmapped_rollout(task):
    obs_size, action_size = SIZES[task]
    out = _rollout(task, "native", (3, 4), 10)
    assert out["obs"].shape == out["next_obs"].shape == (3, 4, 10, obs_size)
    assert out["action"].shape == (3, 4, 10, action_size)
    assert out["reward"].shape == out["terminated"].shape == (3, 4, 10)
    assert out["obs"].dtype == np.float32 and out["reward"].dtype == np.float32
    assert out["terminated"].dtype == np.bool_ and out["truncated"].dtype == np.bool_
    assert np.isfinite(out["next_obs"]).all() and np.isfinite(out["reward"]).all()
    assert out["next_obs"][:, :, -1].reshape(12, -1).std(0).max() > 1e-3  # envs differ


@pytest.mark.optimized
def test_native_vmapped_equals_looped():
    """The same resets and actions (made outside the programs) through one vmapped program and
    through one env at a time: equal to the bit."""
    env, params = _params("halfcheetah")
    keys = jax.random.split(jax.random.key(0), 6)
    actions = jnp.asarray(_grid_actions(np.random.default_rng(1), 6 * 10, 6).reshape(6, 10, 6))

    def play(key, actions):
        _, state = env.reset(key, params)

        def body(state, action):
            obs, state, reward, *_ = env.step(None, state, action, params)
            return state, (obs, reward, state.engine)

        return jax.lax.scan(body, state, actions)[1]

    batched = jax.jit(jax.vmap(jax.vmap(play)))(keys.reshape(2, 3), actions.reshape(2, 3, 10, 6))
    for i in range(6):
        looped = jax.jit(play)(keys[i], actions[i])
        for mine, theirs in zip(looped, batched, strict=True):
            np.testing.assert_array_equal(np.asarray(mine), np.asarray(theirs)[i // 3, i % 3])


def test_native_steps_only_the_active_workers_and_those_as_step_does(monkeypatch):
    """`step_active`: an inactive worker's physics is not stepped (its state stays); the
    active ones' outputs equal `step`'s to the bit (ant: its contact forces' pass too)."""
    env, params = _params("ant")
    _, state = jax.vmap(env.reset, (0, None))(jax.random.split(jax.random.key(0), 4), params)
    action = jnp.asarray(np.random.default_rng(0).uniform(-1, 1, (4, 8)), jnp.float32)
    active = jnp.array([True, False, True, False])
    engine, stepped = native.engine(TASKS["ant"]), []
    host_step = engine._host_step

    def counting(bits, ctrl, active=None):
        stepped.append(None if active is None else int(active.sum()))
        return host_step(bits, ctrl, active)

    monkeypatch.setattr(engine, "_host_step", counting)
    every = jax.vmap(env.step, (None, 0, 0, None))(None, state, action, params)
    some = jax.vmap(env.step_active, (None, 0, 0, None, 0))(None, state, action, params, active)
    assert stepped == [None, 2]  # one host call each; the second steps two rows
    for mine, theirs in zip(jax.tree.leaves(some[:4]), jax.tree.leaves(every[:4]), strict=True):
        np.testing.assert_array_equal(np.asarray(mine)[[0, 2]], np.asarray(theirs)[[0, 2]])
    before, after = np.asarray(state.engine), np.asarray(some[1].engine)
    np.testing.assert_array_equal(after[[1, 3]], before[[1, 3]])
    assert not np.array_equal(np.asarray(every[1].engine)[1], before[1])
    assert np.isfinite(some[0]).all() and np.isfinite(some[2]).all()


def test_native_makes_one_host_call_per_step_for_the_whole_batch(monkeypatch):
    engine = native.engine(TASKS["inverted_pendulum"])
    calls = []
    host_step = engine._host_step
    monkeypatch.setattr(engine, "_host_step", lambda b, c: calls.append(c.shape) or host_step(b, c))
    jax.clear_caches()
    _rollout("inverted_pendulum", "native", (2, 5), 7)
    assert calls == [(2, 5, 1)] * 7


def test_truncation_exactly_at_max_steps():
    out = _rollout("inverted_pendulum", "native", (16,), 40, max_steps=5)
    terminated, truncated = out["terminated"], out["truncated"]
    step = np.arange(1, 41)
    np.testing.assert_array_equal(out["time"], np.broadcast_to(step, terminated.shape))
    np.testing.assert_array_equal(truncated, (step >= 5) & ~terminated)
    assert truncated[:, 4].any() and terminated[:, 4:].any()


# -- observation-based termination and reward (imagined rollouts) --------------------------


def test_is_terminal_boundaries():
    """The healthy ranges, open or closed as gymnasium writes them, on hand-made observations."""
    is_terminal = {task: TASKS[task].is_terminal for task in TASKS}
    hopper = np.zeros((4, 11), np.float32)
    hopper[:, 0] = [0.7, 0.71, 1.2, 1.2]
    hopper[:, 1] = [0.0, 0.0, 0.2, 0.19]
    hopper[3, 3] = 100.0  # a joint angle outside (-100, 100)
    np.testing.assert_array_equal(is_terminal["hopper"](hopper), [True, False, True, True])
    walker = np.zeros((5, 17), np.float32)
    walker[:, 0] = [0.8, 0.81, 2.0, 1.99, 1.2]
    walker[:, 1] = [0.0, 0.0, 0.0, 0.0, -1.0]
    np.testing.assert_array_equal(is_terminal["walker2d"](walker), [1, 0, 1, 0, 1])
    ant = np.zeros((5, 105), np.float32)
    ant[:, 0] = [0.2, 1.0, 0.19, 1.01, 0.5]
    ant[4, 20] = np.inf
    np.testing.assert_array_equal(is_terminal["ant"](ant), [0, 0, 1, 1, 1])
    pendulum = np.zeros((4, 4), np.float32)
    pendulum[:, 1] = [0.2, -0.21, 0.21, 0.0]
    pendulum[3, 2] = np.nan
    np.testing.assert_array_equal(is_terminal["inverted_pendulum"](pendulum), [0, 1, 1, 1])


@pytest.mark.parametrize("task", ["halfcheetah", "hopper", "walker2d", "ant", "reacher"])
def test_is_terminal_on_observations_agrees_with_the_env(task):
    out = _parity(task)["ours"]
    terminal = np.asarray(TASKS[task].is_terminal(jnp.asarray(out["obs"])))
    np.testing.assert_array_equal(terminal, out["terminated"])


@pytest.mark.parametrize("task", ["inverted_pendulum", "reacher"])
def test_exact_reward_from_observations(task):
    env, params = _params(task)
    out = _rollout(task, "native", (8,), 30)
    reward = env.reward(out["obs"], out["action"], out["next_obs"], params)
    np.testing.assert_allclose(np.asarray(reward), out["reward"], rtol=1e-5, atol=1e-6)
    assert out["reward"].std() > 0  # the pendulum's terminating steps pay 0 (v5)


def test_reward_is_none_where_obs_does_not_fix_it():
    for task in ("ant", "halfcheetah", "hopper", "walker2d"):
        env, params = _params(task)
        obs_size, action_size = SIZES[task]
        obs, action = jnp.zeros((2, obs_size)), jnp.zeros((2, action_size))
        assert env.reward(obs, action, obs, params) is None


# -- mjx -------------------------------------------------------------------------------------


def test_mjx_steps_the_same_model_and_stays_close_to_native():
    """One MJX compile: the same task definition on MJX, from the same reset states, with the
    same actions. MJX computes in float32 and warm-starts its solver, so it drifts from the C
    engine; over 5 steps of inverted_pendulum the drift stays below 1e-3."""
    mjx_out = _rollout("inverted_pendulum", "mjx", (6,), 5)
    native_out = _rollout("inverted_pendulum", "native", (6,), 5)
    np.testing.assert_allclose(mjx_out["obs"][:, 0], native_out["obs"][:, 0], atol=1e-6)
    np.testing.assert_allclose(mjx_out["next_obs"], native_out["next_obs"], atol=1e-3)
    assert np.abs(mjx_out["next_obs"] - native_out["next_obs"]).max() > 0  # two engines
    np.testing.assert_array_equal(mjx_out["terminated"], native_out["terminated"])


# -- backends, errors, console ---------------------------------------------------------------


def test_auto_backend_is_native_on_cpu_and_bad_names_fail_in_one_line():
    assert envs.mujoco.resolve_backend("auto") == "native"  # the test machines are CPUs
    assert envs.mujoco.resolve_backend("mjx") == "mjx"
    with pytest.raises(ValueError, match="unknown backend 'warp'; valid backends: auto, native"):
        envs.mujoco.resolve_backend("warp")
    with pytest.raises(ValueError, match="unknown MuJoCo task 'humanoid'; valid tasks: ant"):
        envs.mujoco.engine("humanoid", "native")


def test_a_model_mujoco_cannot_load_is_one_line(tmp_path, monkeypatch):
    (tmp_path / "broken.xml").write_text("<mujoco><worldbody><geom type='sphere'/>")
    monkeypatch.setattr(model, "asset_path", lambda asset: str(tmp_path / asset))
    with pytest.raises(model.ModelError) as error:
        model.load("broken.xml")
    assert "cannot load" in str(error.value) and "\n" not in str(error.value)


def test_a_mujoco_run_prints_no_library_noise():
    code = (
        "import jax\nfrom ldn_jax import envs\n"
        "envs.mujoco.engine('halfcheetah', 'mjx')\n"  # imports mujoco.mjx (warp messages)
        "env, params = envs.make('halfcheetah')\n"
        "jax.jit(lambda k: env.reset(k, params)[0])(jax.random.key(0)).block_until_ready()\n"
        "import sys; assert 'brax' not in sys.modules\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout == "" and done.stderr == "", (done.stdout, done.stderr)


def test_a_non_finite_action_is_zero_control_without_mujoco_warnings(tmp_path, monkeypatch, capfd):
    # A diverged policy's NaN actions: MuJoCo would warn on every step (and write
    # MUJOCO_LOG.TXT into the working directory) and reset its state.
    monkeypatch.chdir(tmp_path)
    env, params = _params("inverted_pendulum")
    _, state = env.reset(jax.random.key(0), params)
    step = jax.jit(lambda action: env.step(jax.random.key(1), state, action, params)[0])
    nan, zero = step(jnp.array([jnp.nan])), step(jnp.array([0.0]))
    np.testing.assert_array_equal(np.asarray(nan), np.asarray(zero))
    assert capfd.readouterr() == ("", "")
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


# -- a native training run ---------------------------------------------------------------------


def test_native_run_resumes_to_the_bit(tmp_path):
    """ldn on inverted_pendulum through the native engine, interrupted after 2 of 4 chunks and
    resumed: every metrics line and the final history equal the uninterrupted run's."""
    from ldn_jax.config import from_preset
    from ldn_jax.host.run_dir import read_config as read_run_config
    from ldn_jax.host.training import Interrupted, train
    from tests.test_resume import StopAfter, _lines

    config = from_preset(
        "paper", env="inverted_pendulum", algo="ldn", seeds=2, k=(1.0,), episodes=8, workers=2
    )
    config = dataclasses.replace(config, chunk_iterations=1, backend="native")
    reference, resumed = tmp_path / "reference", tmp_path / "resumed"
    reference.mkdir(), resumed.mkdir()
    summary = train(config, reference, checkpoint_every=1, quiet=True)
    assert summary["backend"] == "native" and summary["imagined_steps"] > 0
    with pytest.raises(Interrupted):
        train(config, resumed, checkpoint_every=1, quiet=True, stop=StopAfter(2))
    assert len(_lines(resumed)) == 2 * 2
    assert read_run_config(resumed).backend == "native"
    train(read_run_config(resumed), resumed, checkpoint_every=1, quiet=True, resume=True)
    assert _lines(resumed) == _lines(reference)
    final = lambda run: np.load(run / "checkpoints" / "final.host.npz")["history/moving_after"]
    np.testing.assert_array_equal(final(resumed), final(reference))


def test_every_task_plays_gymnasiums_step_limit_and_the_paper_reacher_its_1000():
    import gymnasium

    from experiments.paper import common
    from ldn_jax.config import Config, from_preset
    from ldn_jax.host import gym_eval
    from ldn_jax.trainer import Trainer

    for task, spec in envs.mujoco.TASKS.items():
        limit = gymnasium.spec(spec.gymnasium_id).max_episode_steps
        assert envs.make(task)[1].max_steps == limit, task
    assert from_preset("paper", env="reacher", algo="ldn").episode_limit == 50
    assert gym_eval.make_env("reacher").spec.max_episode_steps == 50
    # The paper's reproduction runs reacher for the paper's 1,000 steps, and so does its eval.
    paper = common.run_config(common.SCALES["cpu"], "reacher", "ldn")
    assert paper.max_steps == paper.episode_limit == 1000
    assert gym_eval.make_env("reacher", max_steps=1000).spec.max_episode_steps == 1000
    # A run from before the limit was a setting resumes with the 1,000 steps it trained with.
    stored = from_preset("paper", env="reacher", algo="ldn").to_dict()
    del stored["max_steps"]
    assert Config.from_dict(stored).episode_limit == 1000
    cartpole = from_preset("paper", env="cartpole-v1", algo="a2c", max_steps=7)
    assert Trainer(cartpole).max_steps == 7 and cartpole.steps_per_iteration == 10


@pytest.mark.parametrize("task", ["halfcheetah", "hopper", "inverted_pendulum", "ant-nocfrc"])
def test_a_state_rebuilt_from_an_observation_steps_as_the_env_does(task):
    """`from_observation` puts the env in the state an observation describes (x position 0):
    stepped from the observations of a real rollout it must give the rollout's own next
    observations and rewards (x is not observed and rewards move with its change, not its
    value). `experiments.model_error` and `model.world` "true" step imagined states so."""
    from experiments.model_error import true_world

    env, params = _params(task)
    assert env.observes_state(params)
    keys = jax.random.split(jax.random.key(3), 4)
    actions = jnp.asarray(_grid_actions(np.random.default_rng(2), 4, SIZES[task][1]))

    def first_steps(key, action):
        _, state = env.reset(key, params)
        obs2, state, *_ = env.step(None, state, action, params)  # off the initial pose
        obs3, _, reward, terminated, *_ = env.step(None, state, action, params)
        return obs2, obs3, reward, terminated

    obs, want_obs, want_reward, want_term = jax.vmap(first_steps)(keys, actions)
    got_obs, got_reward, got_term = true_world(env, params)(jax.random.key(0), obs, actions)
    np.testing.assert_allclose(got_obs, want_obs, rtol=1e-4, atol=1e-4)
    # ant's forward velocity reads the torso frame's x as MuJoCo's data holds it after a step
    # (as gymnasium does), which lags the step's last integration; a rebuilt state's frame is
    # at its position exactly, so its first reward differs by about 2e-4 (measured).
    tolerance = 1e-3 if task.startswith("ant") else 1e-4
    np.testing.assert_allclose(got_reward, want_reward, rtol=1e-4, atol=tolerance)
    np.testing.assert_array_equal(got_term, want_term)
    # A step off is not within the tolerance (the test can fail).
    assert np.abs(np.asarray(got_obs) - np.asarray(obs)).max() > 1e-3


def test_the_action_ranking_of_a_perfect_model_is_the_true_one():
    """`experiments.model_error.action_ranking` with the real simulator in the model's place
    (`model.world` "true"): the imagined advantages are the true ones (correlation 1, no
    error); the untrained model's are not."""
    from experiments.model_error import action_ranking
    from ldn_jax.config import from_preset
    from ldn_jax.trainer import Trainer

    found = {}
    for world in ("true", "model"):
        config = from_preset(
            "branched", env="inverted_pendulum", algo="ppo-model", seeds=1, model={"world": world}
        )
        trainer = Trainer(config)
        state = jax.tree.map(lambda x: x[0, 0], trainer.init_batch())
        reset = functools.partial(trainer.env.reset, params=trainer.env_params)
        starts = jax.vmap(reset)(jax.random.split(jax.random.key(5), 64))[0]
        buffer = state.buffer
        obs = buffer.data.obs.at[:64].set(starts)
        buffer = buffer.replace(data=buffer.data.replace(obs=obs), size=jnp.int32(64))
        found[world] = action_ranking(
            trainer, state.replace(buffer=buffer), jax.random.key(1), 3, 8, 8, 64
        )
    assert found["true"]["spread"] > 0
    assert found["true"]["model_true_correlation"] == pytest.approx(1.0, abs=1e-4)
    assert found["true"]["error"] == pytest.approx(0.0, abs=1e-5)
    assert found["model"]["error"] > 10 * found["true"]["error"] + 1e-3


@pytest.mark.parametrize("task", ["ant", "reacher"])
def test_a_task_whose_observation_is_not_its_state_is_not_rebuilt_from_one(task):
    env, params = _params(task)
    assert not env.observes_state(params)
    with pytest.raises(ValueError, match="observation is not its state"):
        env.from_observation(jnp.zeros(SIZES[task][0]), params)
