"""PPO: the clipped surrogate, GAE, and masked steps that change nothing, to the bit."""

from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ldn_jax.config import AgentConfig, PPOConfig, from_preset
from ldn_jax.learners import A2C, PPO
from ldn_jax.learners.base import Segment, canonical
from ldn_jax.learners.ppo import Batch, clipped_surrogate, gae

PPO_CONFIG = from_preset("paper", algo="ppo")
PPO_AGENT, PPO_OWN = PPO_CONFIG.agent, PPO_CONFIG.ppo


def test_clipped_surrogate_hand_computed():
    ratio = jnp.array([0.5, 1.0, 1.5, 1.1, 0.5, 1.5, 1.19])
    advantage = jnp.array([1.0, -1.0, 1.0, -1.0, -1.0, -2.0, 3.0])
    expected = [
        0.5,  # r < 1 - eps, A > 0: min(0.5, 0.8) keeps the unclipped, pessimistic term
        -1.0,  # r = 1: both terms equal r A
        1.2,  # r > 1 + eps, A > 0: clipped at 1.2 A
        -1.1,  # inside the range: r A
        -0.8,  # r < 1 - eps, A < 0: clipped at 0.8 A
        -3.0,  # r > 1 + eps, A < 0: min(-3.0, -2.4) keeps the unclipped r A
        3.57,  # inside the range
    ]
    np.testing.assert_allclose(np.asarray(clipped_surrogate(ratio, advantage, 0.2)), expected)


def _gae_loop(reward, value, next_value, terminated, done, gamma, lam):
    n, workers = reward.shape
    out = np.zeros((n, workers))
    for w in range(workers):
        following = 0.0
        for t in reversed(range(n)):
            delta = reward[t, w] + gamma * (not terminated[t, w]) * next_value[t, w] - value[t, w]
            if done[t, w]:
                following = 0.0
            following = delta + gamma * lam * following
            out[t, w] = following
    return out


def test_gae_matches_a_python_loop_with_terminations_and_truncations():
    rng = np.random.default_rng(0)
    n, workers = 37, 6
    reward, value, next_value = (rng.normal(size=(n, workers)) for _ in range(3))
    done = rng.random((n, workers)) < 0.15
    terminated = done & (rng.random((n, workers)) < 0.5)
    assert (done & ~terminated).any() and terminated.any()
    got = gae(
        *(jnp.asarray(x, jnp.float32) for x in (reward, value, next_value)),
        jnp.asarray(terminated),
        jnp.asarray(done),
        (0.97, 0.9),
    )
    want = _gae_loop(reward, value, next_value, terminated, done, 0.97, 0.9)
    np.testing.assert_allclose(np.asarray(got), want, rtol=1e-5, atol=1e-5)


def test_gae_truncation_bootstraps_and_termination_does_not():
    reward = jnp.ones((1, 2))
    value = jnp.zeros((1, 2))
    next_value = jnp.full((1, 2), 10.0)
    done = jnp.array([[True, True]])
    terminated = jnp.array([[False, True]])  # worker 0 truncated (LD stop), worker 1 terminal
    got = np.asarray(gae(reward, value, next_value, terminated, done, (0.5, 0.95)))
    np.testing.assert_allclose(got, [[1.0 + 0.5 * 10.0, 1.0]])


def _segment(key, n, workers, obs_size=4, n_actions=2, dead_from=None):
    keys = jax.random.split(key, 4)
    weight = jnp.ones((n, workers))
    if dead_from is not None:  # worker w's episode ended (done) at step dead_from[w] - 1
        steps = jnp.arange(n)[:, None]
        weight = (steps < jnp.asarray(dead_from)[None]).astype(jnp.float32)
    done = jnp.zeros((n, workers), bool)
    if dead_from is not None:
        done = jnp.arange(n)[:, None] == jnp.asarray(dead_from)[None] - 1
    return Segment(
        obs=jax.random.normal(keys[0], (n, workers, obs_size)),
        action=jax.random.randint(keys[1], (n, workers), 0, n_actions),
        reward=jax.random.normal(keys[2], (n, workers)),
        next_obs=jax.random.normal(keys[3], (n, workers, obs_size)),
        terminated=done & (jnp.arange(workers) % 2 == 0)[None],
        done=done,
        weight=weight,
    )


def _garbage_in_masked_steps(segment, key):
    """The same segment with NaN, inf and random flags wherever the weight is 0."""
    dead = segment.weight == 0
    k_action, k_flag = jax.random.split(key)
    nan_obs = jnp.where(dead[..., None], jnp.nan, segment.obs)
    return segment.replace(
        obs=nan_obs,
        next_obs=jnp.where(dead[..., None], jnp.inf, segment.next_obs),
        reward=jnp.where(dead, -jnp.inf, segment.reward),
        action=jnp.where(dead, jax.random.randint(k_action, dead.shape, 0, 2), segment.action),
        terminated=jnp.where(dead, jax.random.bernoulli(k_flag, 0.5, dead.shape), False)
        | segment.terminated,
        done=jnp.where(dead, True, segment.done),
    )


def _assert_trees_equal(a, b):
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@pytest.mark.parametrize("learner_cls", [A2C, PPO])
def test_masked_steps_change_nothing_bitwise(learner_cls):
    config = PPO_CONFIG if learner_cls is PPO else from_preset("paper", algo="a2c")
    learner = learner_cls.of(config, obs_size=4, action_spec=2)
    state = learner.init(jax.random.key(0))
    # Imagined-looking segment: workers stopped after 1, 3, 7 and all 12 steps.
    segment = _segment(jax.random.key(1), 12, 4, dead_from=[1, 3, 7, 12])
    garbage = _garbage_in_masked_steps(segment, jax.random.key(2))
    update = jax.jit(learner.update)
    clean, clean_info = update(state, segment, jax.random.key(3))
    dirty, dirty_info = update(state, garbage, jax.random.key(3))
    _assert_trees_equal(clean, dirty)
    _assert_trees_equal(clean_info, dirty_info)
    assert all(np.isfinite(np.asarray(x)).all() for x in jax.tree.leaves(dirty))
    # ...and the live steps did move the parameters.
    moved = jax.tree.map(lambda a, b: bool((a != b).any()), clean.params, state.params)
    assert all(jax.tree.leaves(moved))


def test_ppo_masked_row_far_in_a_narrow_gaussians_tail_keeps_gradients_finite():
    # The canonical (zeroed) masked rows have action 0; a policy whose mean is 0.9 with std
    # 1e-4 gives them log pi = -4e7, so their log-ratio overflows exp after one Adam step.
    spec = SimpleNamespace(discrete=False, size=1, low=(-1.0,), high=(1.0,))
    learner = PPO(PPO_AGENT, obs_size=3, action_spec=spec, ppo=PPO_OWN)
    state = learner.init(jax.random.key(0))
    bias = state.params["actor"]["params"]
    last = sorted(bias)[-1]
    head = dict(bias[last], bias=jnp.array([1.5, -20.0]))
    params = {**state.params, "actor": {"params": {**bias, last: head}}}
    state = state.replace(params=params)
    n, workers = 10, 4
    weight = (jnp.arange(n)[:, None] < jnp.array([2, 5, 7, 10])[None]).astype(jnp.float32)
    # One-step episodes; actions 2 std below the mean pay 1, above it -1: the update moves
    # the mean down, towards the masked rows' action 0, and their log-ratio up.
    mean = learner.greedy(params, jnp.zeros((1, 3)))[0]
    side = jnp.where(jnp.arange(workers) % 2 == 0, -1.0, 1.0)[None].repeat(n, 0)
    segment = Segment(
        obs=jnp.zeros((n, workers, 3)),
        action=(mean + 2e-4 * side)[..., None],
        reward=-side,
        next_obs=jnp.zeros((n, workers, 3)),
        terminated=jnp.ones((n, workers), bool),
        done=jnp.ones((n, workers), bool),
        weight=weight,
    )
    log_pi, _ = learner.log_prob_entropy(params, jnp.zeros((1, 3)), jnp.zeros((1, 1)))
    assert float(log_pi[0]) < -1e4  # the masked row is far in the tail
    new, info = jax.jit(learner.update)(state, segment, jax.random.key(2))
    assert all(np.isfinite(np.asarray(x)).all() for x in jax.tree.leaves(new.params))
    assert all(np.isfinite(float(v)) for v in info.values())


# the jitted memory's update and the same rows' update op by op are held to one bit
# pattern (XLA's older CPU emitters round them apart)
@pytest.mark.optimized
def test_imaginary_memory_learns_only_from_whole_rollouts_in_arrival_order():
    config = from_preset("paper", algo="ppo", agent={"n_steps": 5}, ppo={"epochs": 2})
    learner = PPO(config.agent, obs_size=4, action_spec=2, ppo=config.ppo)
    state = learner.init(jax.random.key(0))
    memory = learner.memory_init(workers=3)  # 15 rows
    learn = jax.jit(learner.learn_from_memory)
    # 1 + 3 + 7 = 11 live rows: fewer than a batch, so nothing is learnt yet.
    first = _segment(jax.random.key(1), 8, 3, dead_from=[1, 3, 7])
    same, memory, info = learn(state, memory, first, jax.random.key(2))
    _assert_trees_equal(same, state)
    assert int(memory.count) == 11 and float(info["updates"]) == 0
    assert float(info["actor_loss"]) == 0.0
    # 11 + 8 = 19 live rows: one update on the first 15 (the 11 kept, then 4 new), 4 left.
    second = _segment(jax.random.key(3), 8, 3, dead_from=[8, 0, 0])
    new, memory, info = learn(state, memory, second, jax.random.key(4))
    assert int(memory.count) == 4 and float(info["updates"]) == 1
    rows = lambda segment: learner.batch(state.params, canonical(segment))
    live = lambda batch: jax.tree.map(lambda x: x[np.asarray(batch.weight) > 0], batch)
    everything = jax.tree.map(
        lambda a, b: jnp.concatenate([a, b]), live(rows(first)), live(rows(second))
    )
    batch = jax.tree.map(lambda x: x[:15], everything)
    expected, _ = learner.learn(state, batch, jax.random.split(jax.random.key(4))[1])
    _assert_trees_equal(new, expected)
    left = jax.tree.map(lambda x: x[15:], everything)
    for name in ("obs", "action", "advantage", "log_prob"):
        np.testing.assert_array_equal(getattr(memory.rows, name)[:4], getattr(left, name))
    assert (np.asarray(memory.rows.weight)[4:] == 0).all()


@pytest.mark.parametrize("value_clip", [None, 0.2])
def test_value_loss_is_clipped_around_v_old_only_with_a_value_clip(value_clip):
    config = from_preset("paper", algo="ppo", ppo={"value_clip": value_clip})
    learner = PPO(config.agent, obs_size=2, action_spec=2, ppo=config.ppo)
    params = learner.init(jax.random.key(0)).params
    obs = jax.random.normal(jax.random.key(1), (6, 2))
    value = learner.value(params, obs)
    action = jnp.zeros(6, jnp.int32)
    log_prob, _ = learner.log_prob_entropy(params, obs, action)
    target = value + 10.0  # far above V: the clip, if any, keeps V_old's own error
    batch = Batch(obs, action, log_prob, value, jnp.ones(6), target, jnp.ones(6))
    _, info = learner.loss(params, batch)
    # V == V_old here, so the clipped and unclipped errors agree: 0.5 x 10^2.
    np.testing.assert_allclose(float(info["critic_loss"]), 50.0, rtol=1e-5)
    moved = batch.replace(value=value - 1.0)  # V_old 1 below V: V may move 0.2 from it
    _, info = learner.loss(params, moved)
    expected = 50.0 if value_clip is None else 0.5 * (10.0 + 1.0 - 0.2) ** 2
    np.testing.assert_allclose(float(info["critic_loss"]), expected, rtol=1e-5)


def test_ppo_fully_masked_segment_leaves_state_bitwise_unchanged():
    learner = PPO(PPO_AGENT, obs_size=4, action_spec=2, ppo=PPO_OWN)
    state = learner.init(jax.random.key(0))
    segment = _segment(jax.random.key(1), 10, 3)
    dead = segment.replace(weight=jnp.zeros_like(segment.weight))
    same, _ = jax.jit(learner.update)(state, dead, jax.random.key(2))
    _assert_trees_equal(same, state)


def test_ppo_any_row_count_pads_to_whole_minibatches():
    config = from_preset("paper", algo="ppo", ppo={"minibatches": 4, "epochs": 2})
    learner = PPO(config.agent, obs_size=3, action_spec=2, ppo=config.ppo)
    state = learner.init(jax.random.key(0))
    segment = _segment(jax.random.key(1), 7, 3, obs_size=3)  # 21 rows, 4 minibatches
    new, info = jax.jit(learner.update)(state, segment, jax.random.key(2))
    assert np.isfinite(float(info["actor_loss"]))
    assert not np.array_equal(
        np.asarray(jax.tree.leaves(new.params)[0]), np.asarray(jax.tree.leaves(state.params)[0])
    )


def test_ppo_update_raises_probability_of_the_better_action():
    # A bandit: action 0 pays 1, action 1 pays 0; one-step episodes, no bootstrap.
    learner = PPO(PPO_AGENT, obs_size=2, action_spec=2, ppo=PPO_OWN)
    state = learner.init(jax.random.key(0))
    n, workers = 16, 8
    action = jnp.tile(jnp.arange(workers) % 2, (n, 1))
    segment = Segment(
        obs=jnp.ones((n, workers, 2)),
        action=action,
        reward=(action == 0).astype(jnp.float32),
        next_obs=jnp.ones((n, workers, 2)),
        terminated=jnp.ones((n, workers), bool),
        done=jnp.ones((n, workers), bool),
        weight=jnp.ones((n, workers)),
    )
    prob = lambda params: jax.nn.softmax(learner.logits(params, jnp.ones((1, 2))))[0, 0]
    new, info = jax.jit(learner.update)(state, segment, jax.random.key(1))
    assert float(prob(new.params)) > float(prob(state.params)) + 0.05
    # The first pass starts at ratio 1; later passes move it, within reason.
    assert 0 <= float(info["clip_fraction"]) <= 1 and float(info["approx_kl"]) >= 0


def test_target_kl_stops_an_update_at_the_first_minibatch_past_it():
    own = lambda target: from_preset(
        "paper", algo="ppo", ppo={"minibatches": 4, "epochs": 3, "target_kl": target}
    )
    segment = _segment(jax.random.key(1), 8, 4)
    runs = {}
    for target in (None, 1e9, 1e-9):
        learner = PPO.of(own(target), obs_size=4, action_spec=2)
        state = learner.init(jax.random.key(0))
        runs[target] = jax.jit(learner.update)(state, segment, jax.random.key(2))
    # Never reached: every step is taken (to float32 rounding: the guard's program fuses
    # differently; with target_kl None the program is the one without a guard).
    for x, y in zip(jax.tree.leaves(runs[1e9][0]), jax.tree.leaves(runs[None][0]), strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-5, atol=1e-8)
    assert float(runs[1e9][1]["kl_stopped"]) == 0.0 and "kl_stopped" not in runs[None][1]
    # Reached at once: the first step (at KL 0, the rollout's own policy) is taken, and the
    # second minibatch finds KL > 0 and stops the 11 steps left.
    (stopped, info), (full, _) = runs[1e-9], runs[None]
    assert float(info["kl_stopped"]) == pytest.approx(11 / 12)
    first = lambda s: np.asarray(jax.tree.leaves(s.params)[0])
    assert not np.array_equal(first(stopped), first(state)) and not np.array_equal(
        first(stopped), first(full)
    )


def test_adams_epsilon_damps_the_steps_of_small_gradients():
    # Adam's step is lr * m / (sqrt(v) + eps): with eps far above every gradient a step is
    # about lr * g / eps, tiny; at optax's 1e-8 every weight moves about lr.
    segment = _segment(jax.random.key(0), n=8, workers=4)
    moved = {}
    for eps in (1e-8, 1e3):
        agent = AgentConfig(adam_eps=eps)
        one_step = PPOConfig(epochs=1, minibatches=1, value_clip=None)
        learner = PPO(agent, obs_size=4, action_spec=2, ppo=one_step)
        state = learner.init(jax.random.key(1))
        new, _ = jax.jit(learner.update)(state, segment, jax.random.key(2))
        change = jax.tree.map(lambda a, b: jnp.abs(a - b).max(), new.params, state.params)
        moved[eps] = max(float(x) for x in jax.tree.leaves(change))
    assert moved[1e-8] == pytest.approx(agent.actor_lr, rel=0.01)  # one Adam step: lr
    assert moved[1e3] < 1e-3 * moved[1e-8]
