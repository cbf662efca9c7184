"""Continuous actions: the Gaussian policy head, clipping, and both learners on a toy task."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ldn_jax.config import AgentConfig, from_preset, validate
from ldn_jax.learners import A2C, PPO
from ldn_jax.learners.base import (
    REWARD_CLIP,
    Gaussian,
    Segment,
    merge_moments,
    training_reward,
)


class Box:
    discrete = False

    def __init__(self, low, high):
        self.low, self.high, self.size = low, high, len(low)


def test_gaussian_mean_in_bounds_and_std_floor():
    policy = Gaussian((-3.0, 0.0), (3.0, 2.0), min_std=1e-4)
    out = jnp.array([[1e6, -1e6, -1e6, -1e6], [0.0, 0.0, 0.0, 0.0]])
    mean, std = policy.mean_std(out)
    np.testing.assert_allclose(np.asarray(mean), [[3.0, 0.0], [0.0, 1.0]])
    np.testing.assert_allclose(np.asarray(std[0]), [1e-4, 1e-4])
    np.testing.assert_allclose(np.asarray(std[1]), np.log(2.0) + 1e-4, rtol=1e-6)


def test_gaussian_log_prob_and_entropy_hand_computed():
    policy = Gaussian((-1.0, -1.0), (1.0, 1.0), min_std=0.0)
    out = jnp.array([np.arctanh(0.5), 0.0, np.log(np.e - 1.0), np.log(np.e**2 - 1.0)])
    action = jnp.array([1.0, -1.0])  # mean (0.5, 0), std (1, 2)
    log_prob, entropy = policy.log_prob_entropy(out, action)
    z1, z2 = (1.0 - 0.5) / 1.0, (-1.0 - 0.0) / 2.0
    expected = -0.5 * (z1**2 + z2**2) - np.log(1.0) - np.log(2.0) - np.log(2 * np.pi)
    np.testing.assert_allclose(float(log_prob), expected, rtol=1e-5)
    np.testing.assert_allclose(
        float(entropy), 1.0 + np.log(2 * np.pi) + np.log(1.0) + np.log(2.0), rtol=1e-5
    )


def test_samples_follow_the_policy_and_env_actions_are_clipped():
    policy = Gaussian((-1.0,), (1.0,), min_std=1e-4)
    out = jnp.tile(jnp.array([np.arctanh(0.2), np.log(np.exp(0.5) - 1.0)]), (50_000, 1))
    samples = np.asarray(policy.sample(jax.random.key(0), out))[:, 0]
    assert abs(samples.mean() - 0.2) < 0.01 and abs(samples.std() - 0.5) < 0.01
    clipped = np.asarray(policy.env_action(jnp.asarray(samples)[:, None]))
    assert clipped.min() >= -1.0 and clipped.max() <= 1.0 and (samples > 1.0).any()


def _bandit_segment(key, n=32, workers=8):
    """One-step episodes; the reward peaks at action 0.5."""
    action = jax.random.uniform(key, (n, workers, 1), minval=-1.0, maxval=1.0)
    return Segment(
        obs=jnp.ones((n, workers, 2)),
        action=action,
        reward=-jnp.square(action[..., 0] - 0.5),
        next_obs=jnp.ones((n, workers, 2)),
        terminated=jnp.ones((n, workers), bool),
        done=jnp.ones((n, workers), bool),
        weight=jnp.ones((n, workers)),
    )


@pytest.mark.parametrize("learner_cls", [A2C, PPO])
def test_learners_move_the_gaussian_mean_toward_the_better_action(learner_cls):
    algo = "ppo" if learner_cls is PPO else "a2c"
    agent = from_preset("paper", algo=algo, agent={"actor_lr": 1e-3}).agent
    learner = learner_cls(agent, obs_size=2, action_spec=Box((-1.0,), (1.0,)))
    state = learner.init(jax.random.key(0))
    mean = lambda params: float(learner.greedy(params, jnp.ones((1, 2)))[0, 0])
    start = mean(state.params)
    update = jax.jit(learner.update)
    for i in range(30):
        state, info = update(state, _bandit_segment(jax.random.key(i)), jax.random.key(100 + i))
    assert all(np.isfinite(float(v)) for v in info.values())
    assert abs(mean(state.params) - 0.5) < abs(start - 0.5) - 0.1


def test_masked_continuous_steps_change_nothing_bitwise():
    learner = PPO(AgentConfig(), obs_size=2, action_spec=Box((-1.0,), (1.0,)))
    state = learner.init(jax.random.key(0))
    segment = _bandit_segment(jax.random.key(1), n=6, workers=3)
    segment = segment.replace(weight=segment.weight.at[3:, 1].set(0.0))
    dead = segment.weight == 0
    garbage = segment.replace(
        action=jnp.where(dead[..., None], jnp.nan, segment.action),
        reward=jnp.where(dead, jnp.inf, segment.reward),
    )
    clean, _ = jax.jit(learner.update)(state, segment, jax.random.key(2))
    dirty, _ = jax.jit(learner.update)(state, garbage, jax.random.key(2))
    for a, b in zip(jax.tree.leaves(clean), jax.tree.leaves(dirty), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.optimized
def test_running_moments_equal_numpy_over_all_live_rows_in_any_batching():
    rng = np.random.default_rng(0)
    x = rng.normal(3.0, [0.5, 2.0, 10.0], size=(60, 3)).astype(np.float32)
    weight = (rng.random(60) > 0.3).astype(np.float32)
    x_dirty = np.where(weight[:, None] > 0, x, np.nan)  # masked rows may hold anything
    stats = {"mean": jnp.zeros(3), "var": jnp.ones(3), "count": jnp.zeros(())}
    for rows in (slice(0, 7), slice(7, 7), slice(7, 41), slice(41, 60)):
        stats = merge_moments(stats, jnp.asarray(x_dirty[rows]), jnp.asarray(weight[rows]))
    live = x[weight > 0]
    assert float(stats["count"]) == len(live)
    np.testing.assert_allclose(np.asarray(stats["mean"]), live.mean(0), rtol=1e-5)
    np.testing.assert_allclose(np.asarray(stats["var"]), live.var(0), rtol=1e-4)
    empty = merge_moments(stats, jnp.asarray(x_dirty[:5]), jnp.zeros(5))
    for a, b in zip(jax.tree.leaves(empty), jax.tree.leaves(stats), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.parametrize("learner_cls", [A2C, PPO])
def test_observation_statistics_standardise_inputs_and_no_gradient_moves_them(learner_cls):
    agent = AgentConfig(normalize_obs=True, obs_clip=4.0)
    learner = learner_cls(agent, obs_size=2, action_spec=Box((-1.0,), (1.0,)))
    state = learner.init(jax.random.key(0))
    obs = jnp.array([[[10.0, -4.0]], [[30.0, -4.0]], [[1e6, 1e6]]])  # [n=3, W=1, 2]
    weight = jnp.array([[1.0], [1.0], [0.0]])
    segment = Segment(obs, jnp.zeros((3, 1, 1)), jnp.zeros((3, 1)), obs, *[weight == 2] * 2, weight)
    state = learner.observe(state, segment)
    stats = state.params["obs_norm"]
    np.testing.assert_allclose(np.asarray(stats["mean"]), [20.0, -4.0])
    np.testing.assert_allclose(np.asarray(stats["var"]), [100.0, 0.0])
    z = learner.normalized(state.params, jnp.array([30.0, -3.0]))
    np.testing.assert_allclose(np.asarray(z), [1.0, 4.0], rtol=1e-5)
    # The policy's input is the standardised observation.
    plain = learner_cls(AgentConfig(), obs_size=2, action_spec=Box((-1.0,), (1.0,)))
    same = {k: v for k, v in state.params.items() if k != "obs_norm"}
    np.testing.assert_allclose(
        np.asarray(learner.logits(state.params, jnp.array([30.0, -3.0]))),
        np.asarray(plain.logits(same, z)),
        rtol=1e-6,
    )
    segment = _bandit_segment(jax.random.key(1), n=4, workers=2)
    new, _ = jax.jit(learner.update)(state, segment, jax.random.key(2))
    for a, b in zip(jax.tree.leaves(new.params["obs_norm"]), jax.tree.leaves(stats), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert not np.allclose(
        np.asarray(new.params["actor"]["params"]["Dense_0"]["kernel"]),
        np.asarray(state.params["actor"]["params"]["Dense_0"]["kernel"]),
    )
    assert "obs_norm" not in plain.init(jax.random.key(0)).params


@pytest.mark.parametrize("learner_cls", [A2C, PPO])
def test_reward_statistics_follow_each_workers_discounted_return_across_segments(learner_cls):
    agent = AgentConfig(normalize_reward=True, gamma=0.5, reward_scale=2.0)
    learner = learner_cls(agent, obs_size=2, action_spec=Box((-1.0,), (1.0,)), workers=2)
    state = learner.init(jax.random.key(0))
    rng = np.random.default_rng(0)
    reward = rng.normal(size=(6, 2)).astype(np.float32)
    done = np.zeros((6, 2), bool)
    done[2, 0] = True  # worker 0's episode ends at step 2 of the first segment
    weight = np.ones((6, 2), np.float32)
    weight[4, 1] = 0.0  # a masked row moves nothing
    reward[4, 1] = np.nan
    expected, running = [], np.zeros(2)
    for t in range(6):
        for w in range(2):
            if weight[t, w]:
                running[w] = 0.5 * running[w] + reward[t, w]
                expected.append(running[w])
                running[w] = 0.0 if done[t, w] else running[w]
    base = _bandit_segment(jax.random.key(1), n=3, workers=2)
    for rows in (slice(0, 3), slice(3, 6)):  # two segments: the returns carry over
        segment = base.replace(
            reward=jnp.asarray(reward[rows]),
            done=jnp.asarray(done[rows]),
            weight=jnp.asarray(weight[rows]),
        )
        state = learner.observe(state, segment)
    stats = state.params["reward_norm"]
    np.testing.assert_allclose(np.asarray(stats["return"]), running, rtol=1e-5)
    np.testing.assert_allclose(float(stats["var"][0]), np.var(expected), rtol=1e-4)
    assert float(stats["count"]) == len(expected)
    trained = learner.training_reward(state.params, base)
    std = np.sqrt(np.var(expected) + 1e-8)
    want = 2.0 * np.clip(np.asarray(base.reward) / std, -REWARD_CLIP, REWARD_CLIP)
    np.testing.assert_allclose(np.asarray(trained), want, rtol=1e-5)
    # No gradient moves the statistics.
    new, _ = jax.jit(learner.update)(state, base, jax.random.key(2))
    for a, b in zip(
        jax.tree.leaves(new.params["reward_norm"]), jax.tree.leaves(stats), strict=True
    ):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert (
        "reward_norm"
        not in learner_cls(AgentConfig(), 2, Box((-1.0,), (1.0,))).init(jax.random.key(0)).params
    )


def test_reward_scale_multiplies_the_training_reward_after_the_terminal_one():
    segment = _bandit_segment(jax.random.key(0), n=2, workers=1)
    segment = segment.replace(terminated=jnp.array([[False], [True]]))
    agent = AgentConfig(reward_scale=0.1, terminal_reward=-5.0)
    np.testing.assert_allclose(
        np.asarray(training_reward(segment, agent)),
        [[0.1 * float(segment.reward[0, 0])], [-0.5]],
        rtol=1e-6,
    )


def test_a_saved_policy_standardises_observations_with_its_own_statistics(tmp_path):
    from ldn_jax import load_policy
    from ldn_jax.host.run_dir import RunDir
    from ldn_jax.host.training import train
    from ldn_jax.trainer import Trainer

    config = from_preset(
        "paper", env="cartpole-v1", algo="ppo", seeds=1, episodes=8, workers=4,
        agent={"normalize_obs": True},
    )  # fmt: skip
    summary = train(config, tmp_path, checkpoint_every=0, quiet=True)
    trainer = Trainer(config)
    state = RunDir(tmp_path).restore_final(jax.eval_shape(trainer.init_batch))
    params = jax.tree.map(lambda x: x[0, 0], state.learner.params)
    stats = params["obs_norm"]
    assert int(stats["count"]) == summary["env_steps"]
    act = load_policy(tmp_path)
    rng = np.random.default_rng(0)
    for obs in rng.normal(0.0, 0.1, size=(20, 4)).astype(np.float32):
        z = np.clip((obs - stats["mean"]) / np.sqrt(stats["var"] + 1e-8), -10.0, 10.0)
        logits = trainer.learner.actor.apply(params["actor"], jnp.asarray(z))
        assert act(obs) == int(np.argmax(logits))


def test_locomotion_ppo_scales_rewards_and_standardises_observations():
    for env in ("halfcheetah", "hopper", "walker2d", "ant"):
        agent = from_preset("paper", env=env, algo="ppo-ldn").agent
        assert agent.normalize_obs
        # the A2C family standardises halfcheetah's and walker2d's observations, and hopper's
        # observations and rewards (measured there); ant's neither (unmeasured)
        a2c = from_preset("paper", env=env, algo="ldn").agent
        assert a2c.normalize_obs == (env != "ant") and a2c.hidden_layers == 1
        assert a2c.normalize_reward == (env == "hopper")
    agent = from_preset("paper", env="halfcheetah", algo="ppo").agent
    assert agent.reward_scale == 0.1 and not agent.normalize_reward
    # Baselines' MuJoCo PPO: rewards over the return's std, one rollout per iteration.
    for env in ("hopper", "walker2d", "ant"):
        config = from_preset("paper", env=env, algo="ppo-model")
        assert config.agent.normalize_reward and config.agent.reward_scale == 1.0
        assert config.schedule == "steps" and config.steps_per_iteration == config.agent.n_steps
        assert (config.agent.hidden_layers, config.agent.actor_hidden) == (2, 64)
    for env in ("inverted_pendulum", "reacher", "cartpole-v1"):
        agent = from_preset("paper", env=env, algo="ppo").agent
        assert not agent.normalize_obs and agent.reward_scale == 1.0


def test_fast_preset_sets_its_constants_and_budget_and_flags_still_win():
    config = from_preset("fast", env="cartpole-v1", algo="a2c")
    assert config.steps == 600_000 and config.schedule == "steps" and config.k == (1.0,)
    assert config.agent.gamma == 0.99 and config.agent.reward_scale == 0.1
    assert config.agent.normalize_obs and config.agent.actor_lr == 1e-3
    ppo = from_preset("fast", env="cartpole-v1", algo="ppo")
    assert ppo.steps == 300_000 and not ppo.agent.normalize_obs and ppo.agent.reward_scale == 1.0
    given = from_preset("fast", env="cartpole-v1", algo="ldn", episodes=50, k=(0.5, 1.0))
    assert (given.episodes, given.steps, given.k) == (50, None, (0.5, 1.0))  # flags win
    paper = from_preset("paper", env="cartpole-v1", algo="a2c")
    assert paper.steps is None and paper.schedule == "episodes"
    # Each CartPole stops where every greedy episode lasts to its step limit.
    assert [from_preset("fast", env=f"cartpole-v{v}").solved_return for v in range(3)] == [
        200.0, 500.0, 1000.0
    ]  # fmt: skip
    assert paper.solved_return is None
    assert from_preset("fast", env="cartpole-v1", solved_return=None).solved_return is None


def test_continuous_defaults_normalise_the_model():
    config = from_preset("paper", env="inverted_pendulum", algo="ldn")
    assert config.model.normalize and config.model.predict_delta
    assert config.agent.entropy_beta == 0.0 and config.agent.actor_lr == 1e-3
    cartpole = from_preset("paper", env="cartpole-v1", algo="ldn")
    assert not cartpole.model.normalize and cartpole.agent.actor_lr == 1e-3
    ppo = from_preset("paper", env="inverted_pendulum", algo="ppo-ldn")
    assert ppo.ppo.value_clip is None and (ppo.ppo.epochs, ppo.ppo.minibatches) == (10, 10)
    assert ppo.imagine.mode == "memory"
    assert from_preset("paper", env="cartpole-v1", algo="ppo").ppo.value_clip == 0.2


@pytest.mark.mujoco
def test_ldn_trains_on_inverted_pendulum_end_to_end(tmp_path):
    from ldn_jax import load_policy
    from ldn_jax.host.training import train

    config = from_preset(
        "paper", env="inverted_pendulum", algo="ldn", seeds=1, episodes=4, workers=2
    )
    summary = train(config, tmp_path, checkpoint_every=0, quiet=True)
    run = summary["runs"][0]
    assert run["diverged"] is None and np.isfinite(run["final_moving_return"])
    assert summary["imagined_steps"] > 0
    action = load_policy(tmp_path)(np.zeros(4, np.float32))
    assert action.shape == (1,) and action.dtype == np.float32 and -3.0 <= action[0] <= 3.0


def test_a_state_independent_log_std_starts_at_its_value_and_learns():
    config = AgentConfig(log_std_init=-2.0, hidden_layers=2, actor_hidden=16, critic_hidden=8)
    learner = PPO(config, obs_size=2, action_spec=Box((-1.0, -1.0), (1.0, 1.0)))
    state = learner.init(jax.random.key(0))
    # two hidden layers of the width asked for, then the mean's two outputs (no std outputs)
    kernels = [layer["kernel"].shape for layer in state.params["actor"]["params"].values()]
    assert kernels == [(2, 16), (16, 16), (16, 2)]
    assert [k.shape for k in jax.tree.leaves(state.params["critic"])][1::2] == [
        (2, 8), (8, 8), (8, 1)
    ]  # fmt: skip
    obs = jax.random.normal(jax.random.key(1), (5, 2)) * 10  # any state: the same std
    _, std = learner.policy.mean_std(learner.logits(state.params, obs))
    np.testing.assert_allclose(np.asarray(std), np.exp(-2.0), rtol=1e-6)
    segment = _bandit_segment(jax.random.key(2), n=6, workers=3)
    segment = segment.replace(action=jnp.concatenate([segment.action] * 2, -1))
    new, _ = jax.jit(learner.update)(state, segment, jax.random.key(3))
    assert not np.allclose(np.asarray(new.params["log_std"]), -2.0)  # the actor's optimiser


def test_an_unsquashed_mean_passes_the_bounds_and_the_env_gets_the_bound():
    from ldn_jax.learners.base import Gaussian

    out = jnp.array([[3.0, -0.5, 0.0, 0.0]])  # two means' raw outputs, two std outputs
    squashed = Gaussian((-1.0, 0.0), (1.0, 4.0), min_std=1e-4)
    free = Gaussian((-1.0, 0.0), (1.0, 4.0), min_std=1e-4, squash=False)
    # centre + tanh(raw) * half-width, against centre + raw * half-width
    np.testing.assert_allclose(squashed.mode(out)[0], [np.tanh(3.0), 2.0 + 2.0 * np.tanh(-0.5)])
    np.testing.assert_allclose(free.mode(out)[0], [3.0, 1.0])
    np.testing.assert_allclose(free.env_action(free.mode(out))[0], [1.0, 1.0])
    # the log-probability is the raw sample's under the unbounded mean
    log_prob, _ = free.log_prob_entropy(out, jnp.array([[3.0, 1.0]]))
    _, std = free.mean_std(out)
    expected = -np.log(np.asarray(std[0])).sum() - np.log(2 * np.pi)
    np.testing.assert_allclose(log_prob[0], expected, rtol=1e-6)
    config = AgentConfig(squash_mean=False, log_std_init=0.0)
    learner = PPO(config, obs_size=2, action_spec=Box((-1.0, -1.0), (1.0, 1.0)))
    assert learner.policy.squash is False


def test_log_std_init_is_refused_for_discrete_actions():
    with pytest.raises(ValueError, match="log_std_init is for continuous actions"):
        validate(from_preset("paper", env="cartpole-v1", algo="ppo", agent={"log_std_init": 0.0}))
    with pytest.raises(ValueError, match="squash_mean is for continuous actions"):
        validate(from_preset("paper", env="cartpole-v1", algo="a2c", agent={"squash_mean": False}))


def test_an_unknown_initialiser_is_refused():
    with pytest.raises(ValueError, match="init must be one of normal, fan_in, torch"):
        validate(from_preset("paper", env="cartpole-v1", algo="a2c", agent={"init": "xavier"}))


def test_kept_leaves_leave_the_log_std_and_its_adam_moments_as_they_were():
    """Branched imagination's `imagine.std` "real": an update on imagined rows moves
    every parameter but the log std, whose value and optimiser moments stay the old ones."""
    from ldn_jax.rollout import keep_leaves

    agent = from_preset("paper", algo="ppo", agent={"log_std_init": 0.0, "actor_lr": 1e-2}).agent
    learner = PPO(agent, obs_size=2, action_spec=Box((-1.0,), (1.0,)))
    update = jax.jit(learner.update)
    state, _ = update(
        learner.init(jax.random.key(0)), _bandit_segment(jax.random.key(1)), jax.random.key(4)
    )
    moved, _ = update(state, _bandit_segment(jax.random.key(2)), jax.random.key(3))
    kept = keep_leaves(moved, state, ("log_std",))

    def leaves(tree, name, but="none"):
        """The leaves under a dict key `name` and not under `but` (optax's multi_transform
        files the log std's moments under the label "actor" too)."""
        found = []

        def visit(path, x):
            keys = [getattr(k, "key", None) for k in path]
            if name in keys and but not in keys:
                found.append(np.asarray(x))

        jax.tree_util.tree_map_with_path(visit, tree)
        return found

    # The log std and its moments (in the params and in Adam's mu and nu) are the old ones,
    # and the update did move them, so the test can tell.
    old, new, back = (leaves(s, "log_std") for s in (state, moved, kept))
    assert len(old) >= 3
    assert any(not np.array_equal(a, b) for a, b in zip(old, new, strict=True))
    for a, b in zip(old, back, strict=True):
        np.testing.assert_array_equal(a, b)
    # Everything else is the update's.
    actor = lambda tree: leaves(tree, "actor", but="log_std")
    for a, b in zip(actor(moved), actor(kept), strict=True):
        np.testing.assert_array_equal(a, b)
    assert any(not np.array_equal(a, b) for a, b in zip(actor(state), actor(kept), strict=True))


# a KL of exactly 0: both log-probabilities must round alike, which XLA's older CPU
# emitters do not
@pytest.mark.optimized
def test_a_frozen_actor_takes_no_step_and_leaves_the_clip_and_kl_to_the_critic():
    """`freezing` (branched `imagine.updates` "critic"): PPO's update moves the critic
    only, the actor and log std stay exact, so its approximate KL is 0 and the KL guard never
    stops it."""
    config = from_preset(
        "paper", algo="ppo",
        agent={"log_std_init": 0.0, "actor_lr": 1e-2, "critic_lr": 1e-2, "normalize_obs": True},
        ppo={"target_kl": 1e-4, "max_grad_norm": 0.05},
    )  # fmt: skip
    learner = PPO(config.agent, obs_size=2, action_spec=Box((-1.0,), (1.0,)), ppo=config.ppo)
    start, _ = jax.jit(learner.update)(
        learner.init(jax.random.key(0)), _bandit_segment(jax.random.key(1)), jax.random.key(4)
    )
    frozen = learner.freezing(("actor", "log_std"))
    state, info = jax.jit(frozen.update)(
        start, _bandit_segment(jax.random.key(2)), jax.random.key(3)
    )
    for name in ("actor", "log_std", "obs_norm"):
        old, new = jax.tree.leaves(start.params[name]), jax.tree.leaves(state.params[name])
        for a, b in zip(old, new, strict=True):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert float(info["approx_kl"]) == 0.0 and float(info["kl_stopped"]) == 0.0
    critic = [jax.tree.leaves(s.params["critic"]) for s in (start, state)]
    moved = [not np.array_equal(a, b) for a, b in zip(*critic, strict=True)]
    assert any(moved)
    # Unfrozen, the same update is stopped by the KL guard at once and moves the actor.
    _, info = jax.jit(learner.update)(start, _bandit_segment(jax.random.key(2)), jax.random.key(3))
    assert float(info["kl_stopped"]) > 0


def test_a_scaled_actor_steps_that_share_of_its_whole_step_and_the_critic_its_own():
    """`scaling` (branched `imagine.actor_step`): one optimiser step moves the actor
    and log std by `scale` times the unscaled step from the same gradients, the critic by
    the same step, and the optimiser's moments are the unscaled learner's."""
    agent = from_preset("paper", algo="a2c", agent={"log_std_init": 0.0}).agent
    learner = A2C(agent, obs_size=2, action_spec=Box((-1.0,), (1.0,)))
    start = learner.init(jax.random.key(0))
    grads = jax.tree.map(lambda x: jax.random.normal(jax.random.key(x.size), x.shape), start.params)
    whole = learner.apply_gradients(start, grads)
    quarter = learner.scaling(("actor", "log_std"), 0.25).apply_gradients(start, grads)
    leaves = lambda s, name: jax.tree.leaves(s.params[name])
    step = lambda s, name: [
        np.asarray(b) - np.asarray(a)
        for a, b in zip(leaves(start, name), leaves(s, name), strict=True)
    ]
    for name, share in (("actor", 0.25), ("log_std", 0.25), ("critic", 1.0)):
        for w, q in zip(step(whole, name), step(quarter, name), strict=True):
            assert np.abs(w).max() > 0
            np.testing.assert_allclose(q, share * w, rtol=1e-4, atol=1e-7)  # float32 params
    moments = [jax.tree.leaves(s.opt_state) for s in (whole, quarter)]
    for a, b in zip(*moments, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert learner.scaling(("actor",), 1.0) is learner
