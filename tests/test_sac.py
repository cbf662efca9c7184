"""SAC's pieces (`ldn_jax.learners.sac`): the squashed Gaussian's log-density, the three losses
by hand, the Polyak step, and a one-step continuous bandit it must solve."""

import dataclasses
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


def test_critic_first_steps_the_actor_against_the_critics_after_their_step():
    """`sac.critic_first` (SB3's order): the critics take the same step as in the joint
    update, and the actor's first Adam step, -lr g / (|g| + eps), follows the gradient of its
    loss read at the critics after that step, not before."""
    key, batch = jax.random.key(3), _random_batch(jax.random.key(4), 32, 3, 2)
    joint = SAC(SACConfig(hidden=8), obs_size=3, actions=2)
    first = SAC(SACConfig(hidden=8, critic_first=True), obs_size=3, actions=2)
    state = jax.jit(joint.init)(jax.random.key(0))
    after_joint, _ = jax.jit(joint.update)(state, batch, key)
    after_first, _ = jax.jit(first.update)(state, batch, key)
    close = lambda a, b: jax.tree.map(
        lambda x, y: np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-7), a, b
    )
    close(after_first.params["critic"], after_joint.params["critic"])
    lr, eps = first.config.lr, 1e-8

    @jax.jit
    def adam_step(critics):  # the actor's first Adam step from its loss read at `critics`
        grads = jax.grad(joint.losses, has_aux=True)(state.params, batch, key, critics)[0]
        step = lambda p, g: p - lr * g / (jnp.abs(g) + eps)
        return jax.tree.map(step, state.params["actor"], grads["actor"])

    close(after_first.params["actor"], adam_step(after_joint.params["critic"]))
    close(after_joint.params["actor"], adam_step(state.params["critic"]))
    moved = jax.tree.map(lambda a, b: float(jnp.abs(a - b).max()), after_first.params["actor"],
                         after_joint.params["actor"])  # fmt: skip
    assert max(jax.tree.leaves(moved)) > 0


def _random_batch(key, rows: int, obs: int, actions: int) -> Transitions:
    k = jax.random.split(key, 4)
    return Transitions(
        obs=jax.random.normal(k[0], (rows, obs)),
        action=jax.random.uniform(k[1], (rows, actions), minval=-1, maxval=1),
        reward=jax.random.normal(k[2], (rows,)),
        next_obs=jax.random.normal(k[3], (rows, obs)),
        terminated=jnp.zeros(rows),
    )


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


# -- SAC in the trainer -----------------------------------------------------------------------

SAC_RUN = dict(env="inverted_pendulum", algo="sac", seeds=2, steps=120, chunk_iterations=2)
"""A tiny sac run: 2 seeds, 3 chunks of 2 iterations of 20 steps, updates from step 30."""
SAC_RUN["iteration_steps"] = 20
SAC_RUN["sac"] = {"learning_starts": 30, "hidden": 16, "batch_size": 8, "utd": 2}


def test_the_replay_memory_takes_each_live_row_and_updates_start_at_learning_starts():
    from ldn_jax.config import from_preset
    from ldn_jax.envs.mujoco import ContinuousActions
    from ldn_jax.learners.base import Segment
    from ldn_jax.learners.sac import SACLearner

    sac = {**SAC_RUN["sac"], "learning_starts": 20}
    config = from_preset("paper", **{**SAC_RUN, "steps": 1000, "sac": sac})
    learner = SACLearner.of(config, 3, ContinuousActions(2, (-1.0,) * 2, (1.0,) * 2))
    assert learner.memories.real == 1000  # the run's budget, below the memory's 1M
    state = learner.init(jax.random.key(0))
    keys = jax.random.split(jax.random.key(1), 5)
    n, w = 4, 5  # 20 rows, 13 of them live
    weight = jnp.ones((n, w)).at[:, 0].set(0.0).at[3, 1].set(0.0).at[2:, 2].set(0.0)
    segment = Segment(
        obs=jax.random.normal(keys[0], (n, w, 3)),
        action=jax.random.uniform(keys[1], (n, w, 2), minval=-1, maxval=1),
        reward=jax.random.normal(keys[2], (n, w)),
        next_obs=jax.random.normal(keys[3], (n, w, 3)),
        terminated=jnp.zeros((n, w), bool).at[1, 3].set(True),
        done=jnp.zeros((n, w), bool).at[1, 3].set(True),
        weight=weight,
    )
    update = jax.jit(learner.update)
    first, losses = update(state, segment, keys[4])
    assert int(first.replay.size) == 13 == int(first.replay.cursor)
    live = np.asarray(weight).reshape(-1) > 0
    np.testing.assert_array_equal(
        np.asarray(first.replay.data.obs[:13]), np.asarray(segment.obs).reshape(-1, 3)[live]
    )
    assert float(first.replay.data.terminated[:13].sum()) == 1.0
    same = jax.tree.map(lambda a, b: bool((a == b).all()), first.params, state.params)
    assert all(jax.tree.leaves(same)) and float(losses["critic_loss"]) == 0.0  # 13 < 20
    second, losses = update(first, segment, keys[4])  # 26 rows: it learns
    assert int(second.replay.size) == 26 and float(losses["critic_loss"]) > 0
    moved = jax.tree.map(lambda a, b: bool((a != b).any()), second.params, first.params)
    assert all(jax.tree.leaves(moved["actor"])) and all(jax.tree.leaves(moved["target"]))


def test_the_warm_up_plays_uniform_actions_until_the_memory_holds_random_steps():
    """`sac.random_steps`: uniform actions in [-1, 1] in the real env while the replay memory
    holds fewer rows, the policy's after; 0 (the default) acts as the policy from the start.
    Through the trainer: the first iteration's stored actions are the warm-up's."""
    from ldn_jax.config import from_preset, validate
    from ldn_jax.trainer import Trainer

    def first_actions(random_steps):
        run = {**SAC_RUN, "seeds": 1, "sac": {**SAC_RUN["sac"], "random_steps": random_steps}}
        trainer = Trainer(validate(from_preset("paper", **run)))
        state = jax.jit(trainer.init_state)(jax.random.key(0))
        learner = trainer.learner
        obs = jnp.zeros((3, trainer.obs_size))
        key = jax.random.key(1)
        policy = learner.act(state.learner.params, key, obs)
        warm = learner.behave(state.learner, key, obs)
        full = state.learner.replace(
            replay=state.learner.replay.replace(size=jnp.int32(max(random_steps, 1)))
        )
        np.testing.assert_array_equal(learner.behave(full, key, obs), policy)  # warm-up over
        state, _ = jax.jit(lambda s: trainer.iteration(s, jnp.float32(1.0)))(state)
        replay = state.learner.replay
        return warm, policy, np.asarray(replay.data.action[: replay.size])

    warm, policy, cold = first_actions(0)
    np.testing.assert_array_equal(warm, policy)
    warm, policy, stored = first_actions(100)
    assert not np.allclose(warm, policy) and np.abs(warm).max() <= 1.0
    assert stored.shape == cold.shape == (20, 1) and not np.allclose(stored, cold)
    assert np.abs(stored).max() <= 1.0


def test_a_sac_run_resumes_bitwise_with_its_replay_memory(tmp_path):
    from ldn_jax.config import from_preset
    from ldn_jax.host.run_dir import read_config
    from ldn_jax.host.training import Interrupted, train
    from tests.test_resume import StopAfter, _lines

    config = from_preset("paper", **SAC_RUN)
    whole = train(config, tmp_path / "whole", checkpoint_every=1, quiet=True)
    part = tmp_path / "part"
    with pytest.raises(Interrupted):
        train(config, part, checkpoint_every=1, quiet=True, stop=StopAfter(2))
    resumed = train(read_config(part), part, checkpoint_every=1, quiet=True, resume=True)
    assert _lines(part) == _lines(tmp_path / "whole") and resumed["resumes"] == 1
    assert [r["eval_return"] for r in resumed["runs"]] == [r["eval_return"] for r in whole["runs"]]
    first = _lines(part)[0]
    assert {"real_critic_loss", "real_actor_loss", "real_alpha"} <= set(first["losses"])


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--env", "cartpole-v1"], "sac is for continuous actions, and cartpole-v1's are discrete"),
        (["--env", "hopper", "--set", "sac.utd=0"], "sac utd (updates per real step) must be >= 1"),
        (["--env", "hopper", "--set", "sac.random_steps=-1"], "sac random_steps must be >= 0"),
        (["--env", "hopper", "--set", "schedule=episodes"], "it needs schedule 'steps'"),
        (["--env", "hopper", "--stop", "ld"], "sac imagines none"),
    ],
)
def test_bad_sac_settings_are_one_line(argv, needle):
    from ldn_jax.host import flags
    from ldn_jax.host.settings import UsageError

    with pytest.raises(UsageError) as error:
        flags.build_config(flags.parse_args(["--algo", "sac", *argv]))
    assert needle in str(error.value) and "\n" not in str(error.value)


def test_a_run_shorter_than_learning_starts_is_warned_in_one_line(tmp_path, monkeypatch, capsys):
    """On the locomotion tasks updates start at 10,000 rows: a shorter `sac` run trains
    nothing, and the training command says so before it starts (and not otherwise)."""
    from ldn_jax.config import advisories, from_preset
    from ldn_jax.host import run
    from ldn_jax.host.settings import UsageError

    def refuse(*args, **kwargs):
        raise UsageError("stopped before training")

    monkeypatch.setattr(run, "train", refuse)
    lines = {}
    for steps in (5_000, 10_000):
        argv = ["--env", "hopper", "--algo", "sac", "--steps", str(steps)]
        assert run.main([*argv, "--out", str(tmp_path / str(steps))]) == 2
        lines[steps] = capsys.readouterr().err.splitlines()
    assert lines[10_000] == ["error: stopped before training"]
    (warning, error) = lines[5_000]
    assert warning.startswith("warning: sac makes no update: it plays at most 5,000 real steps")
    assert "sac.learning_starts (10,000)" in warning and error == lines[10_000][0]
    # runs stop at whole iterations (1,000 steps): 9,001 steps play 10,000, the last updates
    warned = lambda **run: bool(advisories(from_preset("paper", algo="sac", **run)))
    assert not warned(env="hopper", steps=9_001) and warned(env="hopper", steps=9_000)
    # an episodes budget: at most 9 episodes of 1,000 steps
    assert warned(env="hopper", episodes=9) and not warned(env="hopper", episodes=10)
    # the pendulum starts at 1,000 rows; another learner has no replay memory
    assert not warned(env="inverted_pendulum", steps=5_000)
    assert not advisories(from_preset("paper", env="hopper", algo="ppo", steps=500))


# -- sac-model and sac-ldn: MBPO's branches into a model memory --------------------------------

MBPO_RUN = dict(env="hopper", algo="sac-model", seeds=1, steps=60, iteration_steps=20)
MBPO_RUN["sac"] = {"learning_starts": 20, "hidden": 16, "batch_size": 20, "model_retain": 2}
MBPO_RUN["sac"] |= {"random_steps": 20}
MBPO_RUN["imagine"] = {"branches": 6}
MBPO_RUN["model"] = {"hidden": 16, "hidden_layers": 1, "early_stop": False, "updates": 2}
MBPO_RUN["stop"] = {"horizon_max": 2, "horizon_from": 20, "horizon_to": 40}


def test_mbpo_branches_start_in_r_and_fill_a_model_memory_of_the_retained_iterations():
    """With a learned termination (`imagine.termination`): the same branches, and one check of
    the termination at the end."""
    from ldn_jax.config import from_preset, validate
    from ldn_jax.trainer import Trainer

    plain = Trainer(validate(from_preset("branched", **MBPO_RUN)))
    plain = jax.eval_shape(plain.init_state, jax.random.key(0))  # the layout: no arrays built
    assert plain.model.termination is None and plain.buffer.data.terminated is None
    run = {**MBPO_RUN, "steps": 80, "imagine": {**MBPO_RUN["imagine"], "termination": "learned"}}
    config = validate(from_preset("branched", **run))  # 4 iterations: the last checks it
    trainer = Trainer(config)
    learner = trainer.learner
    # 6 branches of at most 2 steps (the schedule's `horizon_max`) an iteration, for 2
    # iterations
    assert learner.memories.imagined == 2 * 6 * 2 and learner.memories.real_share == 0.05
    state = jax.jit(trainer.init_state)(jax.random.key(0))
    step = jax.jit(lambda s: trainer.iteration(s, jnp.float32(1.0)))
    sizes, added = [], []
    for _ in range(3):
        before = int(state.learner.imagined.cursor)
        state, _ = step(state)
        sizes.append(int(state.learner.imagined.size))
        added.append((int(state.learner.imagined.cursor) - before) % learner.memories.imagined)
        memory, real = state.learner.imagined, state.buffer
        starts = np.asarray(memory.data.obs[: memory.size])
        stored = np.asarray(real.data.obs[: real.size])
        # every imagined row's observation is a real one or an imagined successor; the
        # first step of a branch starts in R: at least `branches` rows are states of R
        in_r = (np.abs(starts[:, None, :] - stored[None, :, :]).max(-1) == 0).any(1)
        assert in_r.sum() >= 6
    # one step per branch before 20 real steps, two from 40 (a predicted fall ends one
    # sooner): the rows grow with the horizon from the same 6 starts (MBPO's layout)
    assert added[0] == 6 and 6 < added[2] <= 12, added
    # 2 iterations' rows kept: the third overwrites the first's (the ring wrapped)
    assert (
        sizes[-1] == min(learner.memories.imagined, sum(added))
        and int(state.learner.replay.size) == 60
    )
    _learned_termination_ends_the_imagined_steps_it_predicts(state, step)


def _learned_termination_ends_the_imagined_steps_it_predicts(state, step):
    from ldn_jax.dynamics import Termination
    from ldn_jax.envs.mujoco.tasks import TASKS

    real = state.buffer
    stored = np.asarray(real.data.terminated[: real.size])
    truth = np.asarray(TASKS["hopper"].is_terminal(real.data.next_obs[: real.size]))
    assert ((stored == 1.0) == truth).all()  # the real test, kept with each row
    # a classifier sure of termination everywhere ends every imagined step
    params = state.model.termination.params
    last = max(params["params"])
    sure = jax.tree.map(lambda x: x, params)
    sure["params"][last]["bias"] = jnp.full_like(sure["params"][last]["bias"], 100.0)
    done = Termination(sure, state.model.termination.opt_state)
    state = state.replace(model=state.model.replace(termination=done))
    start = int(state.learner.imagined.cursor)
    state, metrics = step(state)
    assert np.isfinite(float(metrics["termination_loss"]))
    memory = state.learner.imagined
    count = (int(memory.cursor) - start) % memory.capacity  # the ring may wrap
    added = np.asarray(memory.data.terminated)[(start + np.arange(count)) % memory.capacity]
    assert count > 0 and (added == 1.0).all()


def test_a_batch_mixes_the_real_share_of_real_rows_once_the_model_memory_holds_some():
    from ldn_jax.buffer import Buffer
    from ldn_jax.config import SACConfig
    from ldn_jax.envs.mujoco import ContinuousActions
    from ldn_jax.learners.sac import Memories, SACLearner

    actions = ContinuousActions(1, (-1.0,), (1.0,))
    learner = SACLearner(
        from_preset_agent(), SACConfig(batch_size=20), 1, actions, Memories(10, 10, 0.25)
    )
    state = learner.init(jax.random.key(0))
    full = lambda value: jax.tree.map(lambda x: jnp.full_like(x, value), state.replay.data)
    replay = Buffer(full(1.0), jnp.int32(10), jnp.int32(0))
    empty = state.imagined  # the model memory as a run starts: no rows
    imagined = Buffer(full(-1.0), jnp.int32(10), jnp.int32(0))
    alone = learner.sample(replay, empty, jax.random.key(1))
    assert (np.asarray(alone.obs) == 1.0).all()  # nothing imagined yet: all real
    mixed = learner.sample(replay, imagined, jax.random.key(1))
    assert (np.asarray(mixed.obs) == 1.0).sum() == 5  # round(20 x 0.25)


def from_preset_agent():
    from ldn_jax.config import from_preset

    return from_preset("paper", env="hopper", algo="sac").agent


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--algo", "sac-model", "--env", "hopper"], "sac-model branches from real states"),
        (
            ["--algo", "sac-ldn", "--env", "hopper", "--preset", "branched",
             "--set", "sac.model_retain=0"],
            "sac model_retain must be >= 1",
        ),
        (["--algo", "sac-model", "--preset", "branched", "--env", "hopper", "--stop", "ld"],
         "sac-model with stop 'ld' is sac-ldn"),
        (["--algo", "sac-model", "--preset", "branched", "--env", "hopper",
          "--set", "imagine.termination=maybe"],
         "unknown termination 'maybe'; valid: known, learned"),
    ],
)  # fmt: skip
def test_bad_mbpo_settings_are_one_line(argv, needle):
    from ldn_jax.host import flags
    from ldn_jax.host.settings import UsageError

    with pytest.raises(UsageError) as error:
        flags.build_config(flags.parse_args(argv))
    assert needle in str(error.value) and "\n" not in str(error.value)


def test_sac_model_runs_mbpos_schedule_and_sac_ldn_the_ld_draw():
    from ldn_jax.config import from_preset

    model = from_preset("branched", env="hopper", algo="sac-model")
    ldn = from_preset("branched", env="halfcheetah", algo="sac-ldn")
    assert model.stop_rule == "mbpo" and model.stop.horizon_max == 15
    assert ldn.stop_rule == "ld" and ldn.imagine.cut == 15 and ldn.iteration_steps == 250
    cheetah = from_preset("branched", env="halfcheetah", algo="sac-model")
    assert cheetah.stop.horizon_max == 1 and cheetah.fit.early_stop
    # MBPO's fit to convergence, capped at 500 minibatch steps a fit on these cores
    assert model.fit.early_stop and model.fit.updates == 500
    # the warm-up: MBPO's 5,000 exploration steps under the preset, over the task's 10,000
    start = lambda c: (c.sac.random_steps, c.sac.learning_starts)
    assert start(model) == start(ldn) == start(cheetah) == (5000, 5000)
    assert start(from_preset("branched", env="hopper", algo="sac")) == (5000, 5000)
    for env in ("halfcheetah", "hopper", "walker2d", "ant", "ant-nocfrc"):
        for algo in ("sac", "sac-model", "sac-ldn"):
            assert start(from_preset("paper", env=env, algo=algo)) == (10_000, 10_000)
    assert start(from_preset("paper", env="inverted_pendulum", algo="sac")) == (0, 1000)


# -- a learned termination (imagine.termination "learned") --------------------------------------


def _hopper_like(key, rows: int):
    """Observations around hopper's healthy box (z > 0.7, |angle| < 0.2): about one in four
    outside it."""
    k_z, k_angle, k_rest = jax.random.split(key, 3)
    z = jax.random.uniform(k_z, (rows, 1), minval=0.6, maxval=1.5)
    angle = jax.random.uniform(k_angle, (rows, 1), minval=-0.25, maxval=0.25)
    return jnp.concatenate([z, angle, jax.random.normal(k_rest, (rows, 9))], axis=-1)


def test_a_learned_termination_weighs_both_classes_alike_and_finds_hoppers_test():
    from ldn_jax.buffer import Transitions as Rows
    from ldn_jax.buffer import buffer_add, buffer_init
    from ldn_jax.config import FitConfig, ModelConfig
    from ldn_jax.dynamics import Dynamics
    from ldn_jax.envs.mujoco.tasks import TASKS

    fit = FitConfig(updates=300, batch_size=256, lr=3e-3)
    dynamics = Dynamics(ModelConfig(hidden=64), 11, 3, termination="learned", fit=fit)
    state = dynamics.init(jax.random.key(0))
    # by hand: at log-odds 0 every row costs log 2, weighted 1/2 over its class's share
    rows = Rows(jnp.zeros((4, 11)), jnp.zeros((4, 3)), jnp.zeros((4, 11)), jnp.zeros(4))
    rows = rows.replace(terminated=jnp.array([1.0, 0.0, 0.0, 0.0]))
    zero = jax.tree.map(jnp.zeros_like, state.termination.params)
    loss = dynamics.termination_loss(zero, state.stats, rows, jnp.float32(0.25))
    assert float(loss) == pytest.approx(np.log(2) * (0.5 / 0.25 + 3 * 0.5 / 0.75) / 4, rel=1e-5)

    test = TASKS["hopper"].is_terminal
    obs = _hopper_like(jax.random.key(1), 4096)
    buffer = buffer_init(4096, 11, 3, terminated=True)
    done = test(obs).astype(jnp.float32)
    batch = Rows(obs, jnp.zeros((4096, 3)), obs, jnp.zeros(4096)).replace(terminated=done)
    buffer = buffer_add(buffer, batch, jnp.ones(4096, bool))
    assert 0.15 < float(done.mean()) < 0.35
    fit = jax.jit(dynamics.fit_termination)
    for i in range(8):
        state, loss = fit(state, buffer, jax.random.key(2 + i))
    fresh = _hopper_like(jax.random.key(99), 4096)
    clear = (jnp.abs(fresh[:, 0] - 0.7) > 0.01) & (jnp.abs(jnp.abs(fresh[:, 1]) - 0.2) > 0.01)
    truth, guess = np.asarray(test(fresh)), np.asarray(dynamics.is_terminal(state, fresh))
    clear = np.asarray(clear)  # a hundredth from the box's sides or more
    assert (guess[truth & clear]).mean() > 0.9 and (~guess[~truth & clear]).mean() > 0.9


def test_the_side_by_side_table_reads_ours_and_sb3s_lines(tmp_path):
    import json

    from experiments.paper import sac as study

    assert study.side_lines(tmp_path) == []
    (tmp_path / "sac" / "side").mkdir(parents=True)
    ours = {"task": "halfcheetah", "seeds": [0], "steps": 100_000, "train_seconds": 1800.0}
    ours |= {"env_steps_per_second": 55.5, "commits": ["abc1234"], "load": "alone"}
    (tmp_path / "sac" / "side" / "x.json").write_text(json.dumps(ours | {"gymnasium": [[5, 7]]}))
    sb3 = {"task": "halfcheetah", "seed": 0, "steps": 100_000, "train_seconds": 2400}
    sb3 |= {"mean": 4321.0, "steps_per_second": 41.7}
    (tmp_path / "sac" / "sb3_sac.jsonl").write_text(json.dumps(sb3) + "\n")
    warm = ours | {"gymnasium": [[9, 9]], "arm": "warmup"}
    (tmp_path / "sac" / "side" / "y.json").write_text(json.dumps(warm))
    rows = [line for line in study.side_lines(tmp_path) if line.startswith("| ours")]
    assert len(rows) == 2 and rows[0].startswith("| ours (`--algo sac`) |")
    assert "| 6 |" in rows[0] and "| 56 |" in rows[0] and "alone" in rows[0]
    assert rows[1].startswith("| ours (`--algo sac`, warm-up) |") and "| 9 |" in rows[1]
    warmup = study.config_of("halfcheetah", 0, 1, 100_000, "warmup")
    assert (
        warmup.sac.random_steps == 10_000
        and study.config_of("halfcheetah", 0, 1, 100_000).sac.random_steps == 0
    )
    assert any(line.startswith("| SB3") and "4,321" in line for line in study.side_lines(tmp_path))


def test_the_study_pools_one_seed_runs_by_task_budget_and_label(tmp_path):
    import json

    from experiments.paper import sac as study

    arms = tmp_path / "sac" / "arms"
    arms.mkdir(parents=True)

    def run(task, first, scores, commit="abc1234", steps=200_000):
        seeds = list(range(first, first + len(scores)))
        data = {"task": task, "seeds": seeds, "steps": steps, "commits": [commit]}
        data |= {"env_steps_per_second": 30.0 * len(scores), "gymnasium": [[s] for s in scores]}
        (arms / f"{task}-sac-s{first}+{len(scores)}-{steps}.json").write_text(json.dumps(data))

    run("hopper", 6, [2400.0])
    run("hopper", 5, [2500.0], commit="def5678")
    run("hopper", 0, [100.0])  # exploratory: a row of its own
    (rows,) = [r for r in study.pooled(tmp_path) if r["label"] == "confirmatory"]
    assert rows["seeds"] == [5, 6] and rows["scores"] == [2500.0, 2400.0]
    assert rows["commits"] == ["def5678", "abc1234"] and not rows["complete"]
    assert not rows["met"] and rows["reached"] == 2  # two seeds are no verdict
    for first, score in zip((7, 8, 9), (2300.0, 100.0, 2600.0), strict=True):
        run("hopper", first, [score])
    (done,) = [r for r in study.pooled(tmp_path) if r["label"] == "confirmatory"]
    assert done["complete"] and done["seeds"] == [5, 6, 7, 8, 9] and done["runs"] == 5
    assert done["met"] == (done["score"]["iqm"] >= 2300.0)
    study.report(tmp_path)
    table = (tmp_path / "sac" / "sac.md").read_text()
    assert "| hopper | 200,000 | 5-9 | plan | confirmatory |" in table
    assert "| hopper | 200,000 | 0 | plan | exploratory |" in table and "pending" in table
    # another arm is exploratory on any seed, a row of its own, and its config is the plan's
    # but for its fields
    warm = {"task": "hopper", "seeds": [5], "steps": 200_000, "commits": ["abc1234"]}
    warm |= {"env_steps_per_second": 30.0, "gymnasium": [[900.0]], "arm": "warmup"}
    (arms / "hopper-sac-warmup-s5+1-200000.json").write_text(json.dumps(warm))
    (other,) = [r for r in study.pooled(tmp_path) if r["arm"] == "warmup"]
    assert other["label"] == "exploratory" and other["seeds"] == [5]
    config, plan = study.config_of("hopper", 5, 1, arm="warmup"), study.config_of("hopper", 5, 1)
    assert (config.sac.random_steps, config.sac.learning_starts) == (10_000, 10_000)
    assert dataclasses.replace(config, sac=plan.sac) == plan
    assert (
        study.run_dir(tmp_path, "hopper", 5, 1, arm="warmup").name
        == "hopper-sac-warmup-s5+1-200000"
    )


def test_the_warmup_plan_selects_on_seeds_0_4_and_confirms_on_fresh_seeds(tmp_path):
    import json

    from experiments.paper import sac as study

    arms = tmp_path / "sac" / "arms"
    arms.mkdir(parents=True)

    def run(task, seed, score, arm="plan"):
        data = {"task": task, "seeds": [seed], "steps": 200_000, "commits": ["abc1234"]}
        data |= {"env_steps_per_second": 30.0, "gymnasium": [[score]]}
        name = "sac" if arm == "plan" else f"sac-{arm}"
        data |= {} if arm == "plan" else {"arm": arm}
        (arms / f"{task}-{name}-s{seed}+1-200000.json").write_text(json.dumps(data))

    plan = [4000.0, 4500.0, 4700.0, 5000.0, 5300.0]
    for seed, score in enumerate(plan, start=5):
        run("halfcheetah", seed, score)
    for seed, score in enumerate([6600.0, 8000.0, 7000.0, 3000.0]):
        run("halfcheetah", seed, score, arm="warmup")
    rows = study.pooled(tmp_path)
    assert study.warmup_decision(rows)["verdict"] == "pending"  # four of five seeds
    run("halfcheetah", 4, 4200.0, arm="warmup")
    decision = study.warmup_decision(study.pooled(tmp_path))
    # 3 of 5 warm-up seeds above every plan seed, one below all, one between: U = 16 of 25
    assert decision["improvement"]["probability"] == pytest.approx(16 / 25)
    assert decision["verdict"] == "adopt"  # a higher IQM and P 0.64 > 0.6
    run("halfcheetah", 4, 3500.0, arm="warmup")  # U = 15 of 25: P 0.6 is not above the bar
    assert study.warmup_decision(study.pooled(tmp_path))["verdict"] == "keep"
    assert study.warmup_tests(study.pooled(tmp_path)) is None
    # the fresh warm-up seeds are a confirmatory row of their own, apart from the plan's
    for seed in range(15, 20):
        run("halfcheetah", seed, 7000.0 + seed, arm="warmup")
        run("hopper", seed, 2000.0 + seed, arm="warmup")
    rows = study.pooled(tmp_path)
    fresh = [r for r in rows if r["label"] == "confirmatory"]
    assert sorted((r["task"], r["arm"], r["seeds"][0]) for r in fresh) == [
        ("halfcheetah", "plan", 5), ("halfcheetah", "warmup", 15), ("hopper", "warmup", 15)
    ]  # fmt: skip
    assert study.warmup_tests(rows) is None  # hopper's plan seeds are missing
    for seed, score in enumerate([1900.0, 2030.0, 1500.0, 2500.0, 1800.0], start=5):
        run("hopper", seed, score)
    tests = study.warmup_tests(study.pooled(tmp_path))
    by_task = {t["task"]: t for t in tests}
    # halfcheetah: every warm-up seed above every plan seed, p = 1 / C(10, 5); hopper: 3 of
    # 5 plan seeds below all five, 2 of 5 not
    assert by_task["halfcheetah"]["p"] == pytest.approx(1 / 252)
    assert by_task["hopper"]["p"] > 0.05 and not by_task["hopper"]["shown"]
    assert by_task["halfcheetah"]["holm_p"] == pytest.approx(2 / 252)
    assert by_task["halfcheetah"]["shown"]
    study.report(tmp_path)
    text = (tmp_path / "sac" / "sac.md").read_text()
    assert "**keep**" in text and "| halfcheetah | `warmup` > `plan` |" in text


def test_the_rule_study_trains_only_the_plans_seeds(tmp_path, capsys, monkeypatch):
    from experiments.paper import sac_rules as study

    for bad in ("3", "10,x", "15"):
        with pytest.raises(SystemExit) as refused:
            study.main(["--seeds", bad, "--results", str(tmp_path)])
        assert refused.value.code == 2 and "--seeds" in capsys.readouterr().err
    trained = []
    monkeypatch.setattr(study, "ensure", lambda task, arm, seed, *rest: trained.append(seed))
    monkeypatch.setattr(study, "report", lambda results: None)
    monkeypatch.setattr(study.common, "compile_cache", lambda results: None)
    study.main(["--seeds", "12,11", "--tasks", "hopper", "--arms", "sac", "--results", "x"])
    assert trained == [12, 11]


def test_the_rule_study_tests_once_every_seed_is_in_and_corrects_by_holm(tmp_path):
    import json

    from experiments.paper import sac_rules as study

    arms = tmp_path / "sac-rules" / "arms"
    arms.mkdir(parents=True)
    base = {"hopper": {"sac": 1000.0, "sac-model": 2000.0, "sac-ldn": 3000.0}}
    base["halfcheetah"] = {"sac": 5000.0, "sac-model": 5000.0, "sac-ldn": 5000.0}

    def write(task, arm, seed):
        data = {"task": task, "arm": arm, "seeds": [seed], "steps": study.STEPS}
        data |= {"commits": ["abc1234"], "train_seconds": 3600.0, "imagined_steps": 20_000}
        data |= {"env_steps": study.STEPS, "gymnasium": [[base[task][arm] + seed, 0.0]]}
        (arms / f"{task}-{arm}-s{seed}.json").write_text(json.dumps(data))

    seeds = range(study.FIRST_SEED, study.FIRST_SEED + study.SEEDS)
    for task in study.TASKS:
        for arm in study.ARMS:
            for seed in seeds:
                if (task, arm, seed) != ("halfcheetah", "sac-ldn", 14):
                    write(task, arm, seed)
    assert study.tests(study.rows_of(tmp_path)) is None  # one seed missing: no verdict
    write("halfcheetah", "sac-ldn", 14)
    rows = study.rows_of(tmp_path)
    hopper = {r["arm"]: r for r in rows if r["task"] == "hopper"}
    assert hopper["sac-ldn"]["scores"][0] == (3010.0 + 0.0) / 2 and len(rows) == 6
    assert hopper["sac"]["imagined_per_real"] == 0.2
    found = study.tests(rows)
    assert len(found) == 6
    # hopper separates cleanly: p = 1/252 each, Holm x6 = 0.024 < 0.05; halfcheetah's tie
    # at the same offsets by seed cannot
    first = found[0]
    assert (first["task"], first["a"], first["b"]) == ("hopper", "sac-ldn", "sac-model")
    assert abs(first["p"] - 1 / 252) < 1e-9 and first["shown"]
    assert not any(t["shown"] for t in found if t["task"] == "halfcheetah")
    study.report(tmp_path)
    assert "not shown at 5 seeds" in (tmp_path / "sac-rules" / "sac-rules.md").read_text()


def test_the_trailing_mean_of_the_curves_by_hand():
    from experiments.paper.plots import smoothed

    returns = np.array([[1.0, 2.0, 3.0, 4.0], [0.0, 0.0, 6.0, 0.0]])
    np.testing.assert_allclose(smoothed(returns, 2), [[1, 1.5, 2.5, 3.5], [0, 0, 3, 3]])
    np.testing.assert_allclose(smoothed(returns, 9), [[1, 1.5, 2, 2.5], [0, 0, 2, 1.5]])


def test_the_curves_read_records_and_leave_out_runs_with_nothing_finished(tmp_path):
    from experiments.paper import cache
    from experiments.paper.plots import step_curves

    runs = tmp_path / "runs" / "sac"
    record = cache.record_of(runs / "hopper-sac-s5+1-200000")
    record.mkdir(parents=True)
    (record / "summary.json").write_text("{}")
    steps = np.arange(1, 41, dtype=np.int32)[None, None] * 1000
    np.savez(record / cache.HISTORY_FILE, env_steps=steps, episode_return=steps / 10.0)
    missing = runs / "hopper-sac-s6+1-200000"
    assert not step_curves({"hopper": {"sac": [missing]}}, tmp_path / "none.png", "t")
    assert not (tmp_path / "none.png").exists()
    panels = {"hopper": {"sac": [runs / "hopper-sac-s5+1-200000", missing]}}
    assert step_curves(panels, tmp_path / "curves.png", "t", {"hopper": 2300.0})
    assert (tmp_path / "curves.png").stat().st_size > 10_000
