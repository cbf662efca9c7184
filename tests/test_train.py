"""The episode player's masks, imagination's stop semantics, and the trainer's invariants."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ldn_jax.buffer import Transitions, buffer_add, buffer_init
from ldn_jax.config import AgentConfig, ModelConfig, StopConfig, from_preset
from ldn_jax.dynamics import MIN_WIDTH, Dynamics
from ldn_jax.imagination import EnvFacts, model_world, stop_rule
from ldn_jax.learners.a2c import A2C
from ldn_jax.rollout import Batch, Player, play_batch, play_episodes
from ldn_jax.trainer import Trainer


def _scripted_world(end_at, terminal):
    """Worker w's episode ends after `end_at[w]` steps, terminated or truncated."""
    end_at, terminal = jnp.asarray(end_at), jnp.asarray(terminal)

    def step(key, time, obs, action, alive):
        time = time + 1
        ends = time >= end_at
        return obs + 1.0, time, jnp.ones_like(obs[:, 0]), ends & terminal, ends & ~terminal, {}

    return step


def _play_scripted(end_at, terminal, n_steps, max_steps, reset=False):
    """The episodes of `_scripted_world` from zero observations, A2C updating every n_steps;
    `reset`: workers restart from the same zero start."""
    learner = A2C(AgentConfig(n_steps=n_steps), obs_size=2, action_spec=2)
    start = (jnp.zeros((len(end_at), 2)), jnp.zeros(len(end_at), jnp.int32))
    player = Player(learner, _scripted_world(end_at, terminal), max_steps)
    params = learner.init(jax.random.key(0))
    if reset:
        return play_batch(jax.random.key(1), params, player, start, Batch(reset=lambda key: start))[
            1
        ]
    return play_episodes(jax.random.key(1), params, player, *start)[1]


def test_masks_end_episodes_and_stop_learning():
    learner = A2C(AgentConfig(n_steps=4), obs_size=2, action_spec=2)
    state = learner.init(jax.random.key(0))
    world = _scripted_world([3, 6, 1], [True, False, False])
    obs = jnp.zeros((3, 2))
    player = Player(learner, world, max_steps=20)
    _, episodes = play_episodes(jax.random.key(1), state, player, obs, jnp.zeros(3, jnp.int32))
    weight = np.asarray(episodes.steps.weight)
    np.testing.assert_array_equal(weight.sum(0), [3, 6, 1])
    for w, n in enumerate([3, 6, 1]):
        assert (weight[:n, w] == 1).all() and (weight[n:, w] == 0).all()
    terminated, done = np.asarray(episodes.steps.terminated), np.asarray(episodes.steps.done)
    assert terminated[2, 0] and done[2, 0]  # terminal: no bootstrap
    assert not terminated[5, 1] and done[5, 1]  # truncation: bootstraps
    np.testing.assert_array_equal(np.asarray(episodes.lengths), [3, 6, 1])
    # The loop stopped at the segment where the last worker ended: later rows are untouched.
    assert (weight[8:] == 0).all()


def test_max_steps_truncates():
    episodes = _play_scripted([100, 100], [True, True], n_steps=3, max_steps=7)
    np.testing.assert_array_equal(np.asarray(episodes.lengths), [7, 7])
    done = np.asarray(episodes.steps.done)
    assert done[6].all() and not np.asarray(episodes.steps.terminated).any()


def test_fully_masked_segment_leaves_learner_bitwise_unchanged():
    learner = A2C(AgentConfig(), obs_size=4, action_spec=2)
    state = learner.init(jax.random.key(0))
    world = _scripted_world([1, 1], [True, True])
    # One live step, then nothing: the update of the segment holding it is the only change.
    player = Player(learner, world, 30)
    new, _ = play_episodes(
        jax.random.key(1), state, player, jnp.zeros((2, 4)), jnp.zeros(2, jnp.int32)
    )
    segment = jax.tree.map(
        lambda x: x[:10],
        play_episodes(jax.random.key(1), state, player, jnp.zeros((2, 4)), jnp.zeros(2, jnp.int32))[
            1
        ].steps,
    )
    expected, _ = learner.update(state, segment)
    for a, b in zip(jax.tree.leaves(new), jax.tree.leaves(expected), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    dead = segment.replace(weight=jnp.zeros_like(segment.weight))
    same, _ = learner.update(state, dead)
    for a, b in zip(jax.tree.leaves(same), jax.tree.leaves(state), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_reset_plays_back_to_back_episodes_until_every_worker_has_ended_one():
    episodes = _play_scripted([3, 6, 1], [True, False, False], 4, 20, reset=True)
    weight, done = np.asarray(episodes.steps.weight), np.asarray(episodes.steps.done)
    # Two segments (worker 1's first episode ends at step 6), every row of them live.
    assert (weight[:8] == 1).all() and (weight[8:] == 0).all()
    np.testing.assert_array_equal(np.flatnonzero(done[:8, 0]), [2, 5])  # restarted at 3
    np.testing.assert_array_equal(np.flatnonzero(done[:8, 1]), [5])
    assert done[:8, 2].all()
    assert np.asarray(episodes.steps.terminated)[:8, 0].sum() == 2
    np.testing.assert_array_equal(np.asarray(episodes.ended), [2, 1, 8])
    # Ended episodes only: 2 x 3 + 6 + 8 x 1 steps over 11 episodes (reward 1 a step).
    length, total = episodes.mean_episode()
    np.testing.assert_allclose([float(length), float(total)], [20 / 11, 20 / 11], rtol=1e-6)


def test_mean_episode_without_reset_is_the_mean_length_and_return():
    episodes = _play_scripted([3, 6, 1], [True, False, False], 4, 20)
    length, total = episodes.mean_episode()
    np.testing.assert_array_equal(np.asarray(episodes.ended), 1)
    np.testing.assert_allclose(float(length), float(episodes.lengths.mean()), rtol=1e-6)
    np.testing.assert_allclose(float(total), float(episodes.returns.mean()), rtol=1e-6)
    np.testing.assert_allclose(float(length), 10 / 3, rtol=1e-6)


def _imagine(ld_stop, trained, bounds=None):
    dynamics = Dynamics(ModelConfig(), obs_size=4, action_size=2)
    model = dynamics.init(jax.random.key(0)).replace(bounds=bounds)
    if trained:  # move M1 far from M0: LD near 1
        model = model.replace(params=jax.tree.map(lambda p: p + 3.0, model.params))
    learner = A2C(AgentConfig(), obs_size=4, action_spec=2)
    never_terminal = lambda obs: jnp.zeros(obs.shape[:-1], bool)
    encode = lambda a: jax.nn.one_hot(a, 2)
    gain = jnp.float32(1.0)
    world = model_world(dynamics, model, EnvFacts(never_terminal, encode), gain, _rule(ld_stop))
    obs = jax.random.uniform(jax.random.key(2), (64, 4), minval=-0.05, maxval=0.05)
    _, episodes = jax.jit(play_episodes, static_argnums=2)(
        jax.random.key(3), learner.init(jax.random.key(4)), Player(learner, world, 50), obs, None
    )
    return episodes


def test_untrained_model_stops_imagination_at_once():
    episodes = _imagine(ld_stop=True, trained=False)
    # M1 == M0: LD = 0, P(stop) = 1, so every imagined episode is one truncated step.
    np.testing.assert_array_equal(np.asarray(episodes.lengths), 1)
    steps = episodes.steps
    assert np.asarray(steps.done[0]).all() and not np.asarray(steps.terminated).any()
    np.testing.assert_array_equal(np.asarray(episodes.extras["ld"][0]), 0.0)
    assert (np.asarray(steps.weight[1:]) == 0).all()


def test_ld_stop_off_runs_to_the_limit_and_trained_model_runs_longer():
    np.testing.assert_array_equal(np.asarray(_imagine(ld_stop=False, trained=False).lengths), 50)
    trained = _imagine(ld_stop=True, trained=True)
    assert np.asarray(trained.lengths).mean() > 5
    weight = np.asarray(trained.steps.weight)
    lengths = np.asarray(trained.lengths)
    for w in range(weight.shape[1]):  # no weight after the stop
        assert (weight[: lengths[w], w] == 1).all() and (weight[lengths[w] :, w] == 0).all()


def test_prediction_outside_the_real_box_truncates_the_imagined_episode():
    free = _imagine(ld_stop=False, trained=True)
    path = np.asarray(free.steps.next_obs)  # [T, W, 4], all 50 steps live
    low, high = path[:10].min(axis=(0, 1)), path[:10].max(axis=(0, 1))
    boxed = _imagine(ld_stop=False, trained=True, bounds=(jnp.asarray(low), jnp.asarray(high)))
    outside = ((path < low) | (path > high)).any(axis=-1)  # [T, W]
    expected = np.where(outside.any(axis=0), outside.argmax(axis=0) + 1, 50)
    assert 10 < expected.min() < 50  # some leave the box, none too soon
    np.testing.assert_array_equal(np.asarray(boxed.lengths), expected)
    last = np.asarray(boxed.lengths) - 1, np.arange(path.shape[1])
    steps = boxed.steps
    assert np.asarray(steps.done)[last].all() and not np.asarray(steps.terminated).any()


def test_buffer_bounds_span_live_observations_and_widen_by_the_support():
    buffer = buffer_add(
        buffer_init(6, obs_size=2, action_size=1),
        Transitions(
            obs=jnp.array([[0.0, 5.0], [1.0, 4.0], [9.0, 9.0]]),
            action=jnp.zeros((3, 1)),
            next_obs=jnp.array([[1.0, 4.0], [2.0, 3.0], [9.0, 9.0]]),
            reward=jnp.zeros(3),
        ),
        jnp.array([True, True, False]),  # the third row is not stored
    )
    dynamics = Dynamics(ModelConfig(support=0.5), obs_size=2, action_size=1)
    low, high = dynamics.buffer_bounds(buffer)
    np.testing.assert_allclose(np.asarray(low), [-1.0, 2.0])  # [0, 2] and [3, 5], +- half
    np.testing.assert_allclose(np.asarray(high), [3.0, 6.0])
    constant = buffer_add(  # a dimension the data never varied in widens from MIN_WIDTH
        buffer_init(2, obs_size=1, action_size=1),
        Transitions(jnp.ones((2, 1)), jnp.zeros((2, 1)), jnp.ones((2, 1)), jnp.zeros(2)),
        jnp.ones(2, bool),
    )
    low, high = Dynamics(ModelConfig(support=0.5), 1, 1).buffer_bounds(constant)
    np.testing.assert_allclose(
        np.asarray([low, high]).ravel(), [1 - 0.5 * MIN_WIDTH, 1 + 0.5 * MIN_WIDTH]
    )
    empty = dynamics.buffer_bounds(buffer_init(6, obs_size=2, action_size=1))
    assert np.isinf(np.asarray(empty)).all()
    state = dynamics.init(jax.random.key(0))
    assert dynamics.within_bounds(state, jnp.full((2,), 1e30))  # unbounded before a fit
    fitted, _ = dynamics.fit(state, buffer, jax.random.key(1))
    np.testing.assert_array_equal(
        np.asarray(dynamics.within_bounds(fitted, jnp.array([[3.0, 6.0], [3.1, 6.0]]))),
        [True, False],
    )


def _config(**overrides):
    base = dict(env="cartpole-v0", algo="ldn", seeds=2, episodes=16, workers=4, chunk_iterations=2)
    base.update(overrides)
    return from_preset("paper", **base)


def _run_chunks(trainer, states, chunks=2):
    states = trainer.init_batch() if states is None else states
    fn = trainer.batched_chunk()
    history = []
    for _ in range(chunks):
        states, metrics = fn(states, trainer.k_values())
        history.append(jax.device_get(metrics))
    return states, history


@pytest.mark.parametrize("algo", ["ldn", "ppo-ldn"])
def test_m0_is_bitwise_frozen_and_m1_moves(algo):
    trainer = Trainer(_config(algo=algo))
    initial = jax.device_get(trainer.init_batch())
    final, _ = _run_chunks(trainer, trainer.init_batch())
    leaves = lambda tree: jax.tree.leaves(jax.device_get(tree))
    for a, b in zip(leaves(final.model.frozen), leaves(initial.model.frozen), strict=True):
        np.testing.assert_array_equal(a, b)
    moved = [
        not np.array_equal(a, b)
        for a, b in zip(leaves(final.model.params), leaves(initial.model.params), strict=True)
    ]
    assert all(moved)
    assert int(final.imagined_steps.min()) > 0
    config = trainer.config
    if config.imagine.mode == "memory":  # the PPO family: every imagined step went to I
        assert config.algo.startswith("ppo")
        rows = config.agent.n_steps * config.workers
        np.testing.assert_array_equal(final.memory.count, final.imagined_steps % rows)


def test_support_box_is_the_buffers_and_episodes_that_leave_it_are_counted():
    trainer = Trainer(_config(algo="a2c-model", model={"support": 0.0}))
    final, history = _run_chunks(trainer, trainer.init_batch())
    outside = np.concatenate([h["imagined_outside"] for h in history], axis=-1)
    assert ((outside >= 0) & (outside <= 1)).all() and outside.max() > 0
    final = jax.device_get(final)
    size = int(final.buffer.size[0, 1])
    seen = np.concatenate(
        [final.buffer.data.obs[0, 1, :size], final.buffer.data.next_obs[0, 1, :size]]
    )
    np.testing.assert_array_equal(final.model.bounds[0][0, 1], seen.min(axis=0))
    np.testing.assert_array_equal(final.model.bounds[1][0, 1], seen.max(axis=0))


def test_observation_statistics_count_every_real_step_and_no_imagined_one():
    # ppo-ldn: its imagined steps go through the imaginary memory, its real ones through PPO
    # updates per segment; A2C's updates share `play_episodes` and `ActorCritic.observe`.
    trainer = Trainer(_config(algo="ppo-ldn", agent={"normalize_obs": True}))
    final, history = _run_chunks(trainer, trainer.init_batch())
    final = jax.device_get(final)
    stats = final.learner.params["obs_norm"]
    assert int(final.imagined_steps.min()) > 0
    np.testing.assert_array_equal(stats["count"], final.env_steps)
    assert np.isfinite(stats["mean"]).all() and (stats["var"] > 0).all()
    assert all(np.isfinite(h["real_actor_loss"]).all() for h in history)


def test_imagined_batch_fills_a_whole_segment_with_back_to_back_episodes():
    trainer = Trainer(_config(imagine={"mode": "batch"}))
    state = trainer.init_state(jax.random.key(0))  # M1 == M0: LD 0, every episode 1 step
    _, real = jax.jit(trainer.real_stage)(state, jax.random.key(2))
    imagine = jax.jit(trainer.imagine_stage)
    _, episodes = imagine(state, jax.random.key(1), jnp.float32(1.0), real)
    n_steps, workers = trainer.config.agent.n_steps, trainer.config.workers
    weight = np.asarray(episodes.steps.weight)
    assert (weight[:n_steps] == 1).all() and (weight[n_steps:] == 0).all()
    np.testing.assert_array_equal(np.asarray(episodes.ended), n_steps)
    assert np.asarray(episodes.steps.done)[:n_steps].all()
    starts = np.asarray(episodes.steps.obs)[:n_steps].reshape(-1, 4)
    assert len(np.unique(starts, axis=0)) > workers  # restarts drawn from the pool


@pytest.mark.parametrize(  # one learner in the default suite (its time); the rest: slow
    "algo", [pytest.param("a2c", marks=pytest.mark.slow), "ldn",
             pytest.param("ppo-ldn", marks=pytest.mark.slow)]
)  # fmt: skip
def test_same_seed_gives_bitwise_identical_metrics(algo):
    trainer = Trainer(_config(algo=algo, k=(1.0, 2.0) if algo.endswith("ldn") else (1.0,)))
    _, first = _run_chunks(trainer, trainer.init_batch())
    _, second = _run_chunks(trainer, trainer.init_batch())
    for m1, m2 in zip(first, second, strict=True):
        for name in m1:
            np.testing.assert_array_equal(m1[name], m2[name], err_msg=name)


@pytest.mark.optimized
def test_vmapped_seeds_equal_seeds_run_one_by_one():
    # Equal to float32 rounding, not bitwise: XLA's CPU kernels for batched (vmapped) matmuls
    # round differently in the last bits from unbatched ones (checked 2026-11-22).
    config = _config(seeds=3)
    trainer = Trainer(config)
    _, batched = _run_chunks(trainer, trainer.init_batch())
    single = jax.jit(trainer.train_chunk)
    k = trainer.k_values()[0]
    for seed in range(config.seeds):
        state = trainer.init_state(jax.random.key(seed))
        for chunk in batched:
            state, metrics = single(state, k)
            for name, value in jax.device_get(metrics).items():
                np.testing.assert_allclose(
                    value, chunk[name][0, seed], rtol=1e-5, atol=1e-6, err_msg=name
                )


@pytest.mark.optimized
def test_a_k_of_a_vmapped_run_equals_a_run_of_that_k_alone():
    # Figure 9 reads K = 1 from Table 4's run and K = 0.5, 2 from a run of its own: each K's
    # lanes are those of one vmapped run (float32 rounding apart, as for seeds above).
    _, both = _run_chunks(Trainer(_config(k=(0.5, 1.0))), None)
    _, alone = _run_chunks(Trainer(_config(k=(1.0,))), None)
    for pair, single in zip(both, alone, strict=True):
        for name in single:
            np.testing.assert_allclose(
                single[name][0], pair[name][1], rtol=1e-5, atol=1e-6, err_msg=name
            )
        assert not np.array_equal(pair["ld_mean"][0], pair["ld_mean"][1])  # K matters


def test_first_seed_starts_what_the_same_seeds_of_a_larger_batch_start():
    """Seeds 2 and 3 alone (`first_seed` 2) start from the states of seeds 2 and 3 of a batch
    of 0..3, keys included, so they train the same (each seed's training reads its own state
    only: `test_vmapped_seeds_equal_seeds_run_one_by_one`) and a run of more seeds adds to an
    earlier one."""
    alone = jax.device_get(Trainer(_config(seeds=2, first_seed=2)).init_batch())
    batch = jax.device_get(Trainer(_config(seeds=4)).init_batch())
    keys = lambda tree: jax.random.key_data(tree.key)
    np.testing.assert_array_equal(keys(alone), keys(batch)[:, 2:])
    assert not np.array_equal(keys(batch)[:, :2], keys(batch)[:, 2:])
    for a, b in zip(jax.tree.leaves(alone), jax.tree.leaves(batch), strict=True):
        if not jax.dtypes.issubdtype(a.dtype, jax.dtypes.prng_key):
            np.testing.assert_array_equal(a, b[:, 2:])


def _rule(ld_stop: bool):
    """The LD draw (ldn) or no stop (a2c-model)."""
    return stop_rule(StopConfig(), "ld" if ld_stop else "none")


@pytest.mark.parametrize(
    ("preset", "env", "algo"),
    [
        ("paper", "cartpole-v1", "ldn"),
        ("branched", "hopper", "ppo-ldn"),  # a learned log std, the model's support box
        ("branched", "hopper", "sac-model"),
    ],
)
def test_an_iteration_returns_the_state_layout_it_was_given(preset, env, algo):
    """Shapes, dtypes and weak types: a leaf that changes between the initial state and an
    iteration's output (a weakly typed constant at init) makes a `jax.jit` of the iteration
    compile again on its second call, with the first call's output (27 s in the MBPO
    branches test; the host loop's ahead-of-time chunk accepts either)."""
    trainer = Trainer(from_preset(preset, env=env, algo=algo, seeds=1, steps=1000))
    start = jax.eval_shape(trainer.init_state, jax.random.key(0))
    after = jax.eval_shape(lambda s: trainer.iteration(s, jnp.float32(1.0))[0], start)
    layout = lambda t: [(x.shape, x.dtype, x.weak_type) for x in jax.tree.leaves(t)]
    assert jax.tree.structure(after) == jax.tree.structure(start)
    changed = [
        jax.tree_util.keystr(path)
        for (path, _), a, b in zip(
            jax.tree_util.tree_leaves_with_path(start), layout(start), layout(after), strict=True
        )
        if a != b
    ]
    assert changed == []
