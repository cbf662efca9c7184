"""Branched imagination (`imagine.start = "real"`), the probabilistic ensemble and the two
rules the field uses (MBPO's horizon schedule, MACURA's adaptive cut): hand-made numbers and
buffers, one short run, and the config's refusals."""

import dataclasses
import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ldn_jax.buffer import (
    HOLDOUT_EVERY,
    Transitions,
    buffer_add,
    buffer_init,
    buffer_sample_recent,
    buffer_sample_split,
)
from ldn_jax.config import FitConfig, ImagineConfig, ModelConfig, StopConfig, from_preset, validate
from ldn_jax.dynamics import Dynamics, gaussian_nll
from ldn_jax.host import flags
from ldn_jax.host.settings import UsageError
from ldn_jax.host.training import train
from ldn_jax.imagination import StepView, macura_threshold, scheduled_horizon, stop_rule
from ldn_jax.trainer import Trainer
from tests.conftest import optimised

BRANCHED = {
    "ld": "ensemble",
    "probabilistic": True,
    "ensemble": 3,
    "elites": 2,
    "hidden": 16,
    "hidden_layers": 2,
    "updates": 5,
}
"""A small probabilistic ensemble for CartPole (3 members, 2 elites)."""


def _dynamics(model: dict, obs_size: int, action_size: int) -> Dynamics:
    """`Dynamics` of a dict of `ModelConfig`'s and `FitConfig`'s fields (as `--set model.X`
    reads them)."""
    fits = {f.name for f in dataclasses.fields(FitConfig)}
    fit = FitConfig(**{k: v for k, v in model.items() if k in fits})
    own = ModelConfig(**{k: v for k, v in model.items() if k not in fits})
    return Dynamics(own, obs_size, action_size, fit=fit)


BRANCHES = {"start": "real", "branches": 6, "ratio": 2.0, "cut": 4}
"""Its branches: 6 side by side, cut after 4 steps, 2 imagined steps per real one."""


def _config(**overrides):
    model = {**BRANCHED, **overrides.pop("model", {})}
    imagine = {**BRANCHES, **overrides.pop("imagine", {})}
    base = dict(env="cartpole-v1", algo="ldn", seeds=2, k=(1.0,), episodes=16, workers=4)
    parts = {"model": model, "imagine": imagine}
    return validate(from_preset("paper", **{**base, "chunk_iterations": 2, **parts, **overrides}))


# -- the rules' numbers ----------------------------------------------------------------------


def test_the_horizon_schedule_grows_linearly_between_its_step_counts():
    config = StopConfig(horizon_min=1, horizon_max=15, horizon_from=20_000, horizon_to=100_000)
    steps = jnp.array([0, 20_000, 40_000, 59_999, 60_000, 100_000, 10**7])
    expected = [1, 1, 4, 7, 8, 15, 15]  # 1 + 14 x (t - 20k) / 80k, rounded down
    assert np.asarray(scheduled_horizon(config, steps)).tolist() == expected
    flat = StopConfig(horizon_min=3, horizon_max=3, horizon_from=5, horizon_to=5)
    assert np.asarray(scheduled_horizon(flat, jnp.array([0, 5, 6]))).tolist() == [3, 3, 3]


def test_macuras_threshold_is_a_scaled_quantile_of_the_first_steps_disagreement():
    first = jnp.array([0.4, 0.1, 0.3, 0.2, 0.5])
    # Quantile 0.75 of (0.1, ..., 0.5): position 3 of 0..4, 0.4; times 2.
    assert float(macura_threshold(first, 0.75, 2.0)) == pytest.approx(0.8)
    # Position 0.9 x 4 = 3.6: 0.4 + 0.6 x 0.1.
    assert float(macura_threshold(first, 0.9, 1.0)) == pytest.approx(0.46)
    rule = stop_rule(StopConfig(), "macura", threshold=jnp.float32(0.46))
    d = jnp.array([0.1, 0.46, 0.47, 3.0])
    view = StepView(*(jnp.zeros((4, 1)),) * 3, jnp.zeros(4), d, jnp.ones(4, bool))
    assert np.asarray(rule(jax.random.key(0), view)).tolist() == [False, False, True, True]


def test_the_gaussian_nll_matches_a_hand_computed_value():
    mean = jnp.array([[0.0, 1.0]])
    log_var = jnp.array([[0.0, math.log(4.0)]])
    target = jnp.array([[1.0, 3.0]])
    # 0.5 (1 + 0 + log 2 pi) and 0.5 (4 / 4 + log 4 + log 2 pi), averaged.
    expected = 0.5 * (
        0.5 * (1 + math.log(2 * math.pi)) + 0.5 * (1 + math.log(4) + math.log(2 * math.pi))
    )
    assert float(gaussian_nll(mean, log_var, target)) == pytest.approx(expected, rel=1e-6)


def test_the_value_equivalence_term_is_the_critics_error_at_the_predicted_next_state():
    """`fit.value_loss`: the fit's loss gains w x mean((V(predicted s') - V(s'))^2) / var
    V(s'), and with it a gradient that the NLL alone does not have."""
    dynamics = _dynamics({**BRANCHED, "value_loss": 2.0}, 4, 2)
    params = jax.tree.map(lambda x: x[0], dynamics.init(jax.random.key(0)).params)
    k = jax.random.split(jax.random.key(1), 4)
    batch = Transitions(
        obs=jax.random.normal(k[0], (32, 4)),
        action=jax.random.normal(k[1], (32, 2)),
        next_obs=jax.random.normal(k[2], (32, 4)),
        reward=jax.random.normal(k[3], (32,)),
    )
    stats = dynamics.init_stats()
    value = lambda obs: 3.0 * obs[..., 0] - obs[..., 2]
    predicted, _ = dynamics.predict(params, batch.obs, batch.action, stats)
    real = np.asarray(value(batch.next_obs))
    expected = np.mean((np.asarray(value(predicted)) - real) ** 2) / (real.var() + 1e-6)
    with_term = float(dynamics.loss(params, batch, stats, value))
    without = float(dynamics.loss(params, batch, stats))
    assert expected > 0.1
    assert with_term - without == pytest.approx(2.0 * expected, rel=1e-4)
    grads = [jax.grad(dynamics.loss)(params, batch, stats, v) for v in (value, None)]
    difference = jax.tree.map(lambda a, b: float(jnp.abs(a - b).max()), *grads)
    assert max(jax.tree.leaves(difference)) > 1e-4


# -- the buffer's split and the elites -------------------------------------------------------


def _buffer(size: int, obs_size: int = 4, action_size: int = 2, capacity: int = 64):
    """A buffer whose transition i has obs and next obs i (every dimension), reward 0."""
    index = jnp.arange(size, dtype=jnp.float32)
    batch = Transitions(
        obs=jnp.repeat(index[:, None], obs_size, axis=1),
        action=jnp.zeros((size, action_size)),
        next_obs=jnp.repeat(index[:, None], obs_size, axis=1),
        reward=jnp.zeros(size),
    )
    return buffer_add(buffer_init(capacity, obs_size, action_size), batch, jnp.ones(size, bool))


def test_the_recent_draw_takes_the_newest_transitions_of_a_wrapped_ring():
    buffer = _buffer(100)  # capacity 64: transitions 36..99 stored, 99 just behind the cursor
    drawn = np.asarray(buffer_sample_recent(buffer, jax.random.key(0), 2000, 10).obs[:, 0])
    assert set(drawn.astype(int)) == set(range(90, 100))
    # Fewer stored than the window: all of them, and nothing of the empty slots.
    drawn = np.asarray(buffer_sample_recent(_buffer(5), jax.random.key(1), 2000, 10).obs[:, 0])
    assert set(drawn.astype(int)) == set(range(5))


def test_the_held_out_slots_are_never_drawn_for_the_fit():
    buffer = _buffer(37)
    held = buffer_sample_split(buffer, jax.random.key(0), 2000, True).obs[:, 0]
    fit = buffer_sample_split(buffer, jax.random.key(1), 2000, False).obs[:, 0]
    assert set(np.asarray(held).astype(int)) == {0, 10, 20, 30}
    assert set(np.asarray(fit).astype(int)) == set(range(37)) - {0, 10, 20, 30}
    assert HOLDOUT_EVERY == 10


def test_elites_are_the_members_with_the_lowest_held_out_error():
    dynamics = _dynamics({**BRANCHED, "elites": 2, "ensemble": 4}, 4, 2)
    state = dynamics.init(jax.random.key(0))
    # Zero every weight (each member predicts no change), then give member i a constant
    # reward: its held-out squared error on still transitions of reward 0 grows with |bias|.
    params = jax.tree.map(jnp.zeros_like, state.params)
    last = max(name for name in params["params"] if name.startswith("Dense"))
    offsets = jnp.array([3.0, 0.5, 2.0, 0.1])
    bias = params["params"][last]["bias"].at[:, 4].set(offsets)  # the reward's mean
    params["params"][last]["bias"] = bias
    state = state.replace(params=params)
    ranked = jax.jit(dynamics._rank)(state, _buffer(50), jax.random.key(1))
    assert np.asarray(ranked.elites).tolist() == [3, 1]
    expected = np.mean([0.1**2 / 5, 0.5**2 / 5])  # the reward is one of 5 outputs
    assert float(ranked.error_scale) == pytest.approx(expected, rel=1e-5)


def test_the_mean_imagined_step_is_the_elites_mean_and_draws_nothing():
    from ldn_jax.imagination import _gaussian_estimate

    obs, action = jax.random.normal(jax.random.key(2), (7, 4)), jnp.ones((7, 2))
    steps = {}
    for step in ("sample", "mean"):
        dynamics = _dynamics({**BRANCHED, "imagined_step": step}, 4, 2)
        state = dynamics.init(jax.random.key(0))
        state = state.replace(elites=jnp.array([2, 0], jnp.int32))
        steps[step] = [
            _gaussian_estimate(dynamics, state, obs, action, jax.random.key(k), "ensemble")[0]
            for k in (1, 5)
        ]
    mean, _ = jax.vmap(dynamics.predict_gaussian, (0, None, None, None))(
        state.params, state.stats, obs, action
    )
    expected = (mean[2] + mean[0]) / 2
    for next_obs, reward in steps["mean"]:
        np.testing.assert_allclose(np.asarray(next_obs), np.asarray(expected[:, :-1]), rtol=1e-6)
        np.testing.assert_allclose(np.asarray(reward), np.asarray(expected[:, -1]), rtol=1e-6)
    (a, _), (b, _) = steps["sample"]  # the default draws: two keys, two steps
    assert not np.allclose(np.asarray(a), np.asarray(b))


# -- branches in a run -----------------------------------------------------------------------


def test_a_branch_starts_from_a_state_in_the_real_buffer():
    trainer = Trainer(_config())
    state = jax.tree.map(lambda x: x[0, 0], trainer.init_batch())
    buffer = _buffer(23, obs_size=4, action_size=2, capacity=trainer.config.model.buffer_capacity)
    buffer = buffer.replace(data=buffer.data.replace(obs=buffer.data.obs * 0.001))
    state = state.replace(buffer=buffer)
    _, real = jax.jit(trainer.real_stage)(state, jax.random.key(3))
    _, episodes = jax.jit(trainer.imagine_stage)(state, jax.random.key(4), jnp.float32(1.0), real)
    steps = episodes.steps
    starts = np.concatenate([np.ones((1, steps.done.shape[1]), bool), np.asarray(steps.done[:-1])])
    known = set(np.round(np.asarray(buffer.data.obs[:23, 0]) * 1000).astype(int))
    first = np.asarray(steps.obs)[starts][:, 0]
    assert len(first) > steps.done.shape[1]  # rollouts ended and new ones began
    assert set(np.round(first * 1000).astype(int)) <= known
    # Every row played is live (the rest of the batch's room is left unplayed) and every
    # rollout is cut at the cut (4) at the latest.
    weight = np.asarray(steps.weight)
    played = weight.any(axis=1)
    assert played.sum() % trainer.config.agent.n_steps == 0 and (weight[played] == 1).all()
    time = np.zeros(weight.shape[1], int)
    for t in np.flatnonzero(played):
        time = np.where(starts[t], 1, time + 1)
        assert (time <= 4).all()
    # `imagine.start_window`: every branch starts from one of the newest 5 transitions.
    trainer = Trainer(_config(imagine={"start_window": 5}))
    _, episodes = jax.jit(trainer.imagine_stage)(state, jax.random.key(4), jnp.float32(1.0), real)
    steps = episodes.steps
    starts = np.concatenate([np.ones((1, steps.done.shape[1]), bool), np.asarray(steps.done[:-1])])
    live = starts & (np.asarray(steps.weight) > 0)  # the unplayed rest of the batch is zeros
    first = np.round(np.asarray(steps.obs)[live][:, 0] * 1000).astype(int)
    assert len(first) > steps.done.shape[1] and set(first) == set(range(18, 23))


def _stages(trainer: Trainer):
    """One seed's state over a hand-made buffer, after its real stage, and after a branched
    stage from it (fed that real play): `(state, after real, after branches)`."""
    state = jax.tree.map(lambda x: x[0, 0], trainer.init_batch())
    buffer = _buffer(23, obs_size=4, action_size=2, capacity=trainer.config.model.buffer_capacity)
    state = state.replace(
        buffer=buffer.replace(data=buffer.data.replace(obs=buffer.data.obs * 0.01))
    )
    real_state, real = jax.jit(trainer.real_stage)(state, jax.random.key(3))
    after, _ = jax.jit(trainer.imagine_stage)(state, jax.random.key(4), jnp.float32(1.0), real)
    return state, real_state, after


def test_a_quarter_actor_step_moves_the_actor_less_on_imagined_rows_only():
    """`imagine.actor_step` 0.25: the branched stage moves the actor, by less than the
    whole step does, and the real stage is the whole learner's."""
    change = {}
    for share in (1.0, 0.25):
        trainer = Trainer(_config(imagine={"actor_step": share}))
        state, real_state, after = _stages(trainer)
        size = lambda a, b: sum(
            float(np.abs(np.asarray(x) - np.asarray(y)).sum())
            for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)
        )
        change[share] = (
            size(state.learner.params["actor"], real_state.learner.params["actor"]),
            size(state.learner.params["actor"], after.learner.params["actor"]),
        )
    assert change[0.25][0] == change[1.0][0] > 0
    assert 0 < change[0.25][1] < 0.6 * change[1.0][1]


def test_critic_only_imagination_moves_the_critic_and_leaves_the_actor():
    """`imagine.updates` "critic": the branched stage's updates train the critic, and
    the actor's parameters and optimiser moments stay as they were; "all" moves both."""
    moved = {}
    for updates in ("all", "critic"):
        trainer = Trainer(_config(imagine={"updates": updates}))
        state, _, after = _stages(trainer)
        differ = lambda a, b: any(
            not np.array_equal(x, y)
            for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)
        )
        old, new = state.learner, after.learner
        moved[updates] = (
            differ(old.params["actor"], new.params["actor"]),
            differ(old.params["critic"], new.params["critic"]),
            differ(old.opt_state, new.opt_state),
        )
        if updates == "critic":
            keep = lambda tree: [
                np.asarray(x)
                for p, x in jax.tree_util.tree_leaves_with_path(tree)
                if "actor" in [getattr(k, "key", None) for k in p]
            ]
            for a, b in zip(keep(old.opt_state), keep(new.opt_state), strict=True):
                np.testing.assert_array_equal(a, b)
    assert moved["all"] == (True, True, True)
    assert moved["critic"] == (False, True, True)


def test_imagined_epochs_set_the_passes_over_imagined_rows_only():
    """`imagine.epochs`: the branched stage's PPO updates make that many passes (Adam's
    step count grows in proportion), while the real stage keeps the learner's own."""
    steps = {}
    for epochs in (0, 3):
        config = _config(algo="ppo-model", imagine={"epochs": epochs})
        trainer = Trainer(config)
        state, real_state, after = _stages(trainer)
        count = lambda s: max(
            int(x)
            for p, x in jax.tree_util.tree_leaves_with_path(s.learner.opt_state)
            if "count" in jax.tree_util.keystr(p)
        )
        steps[epochs] = (count(real_state) - count(state), count(after) - count(state))
    own = config.ppo.epochs  # 0 takes the learner's own
    assert own != 3 and steps[0][0] > 0 and steps[0][0] == steps[3][0]
    assert steps[3][1] > 0 and steps[0][1] * 3 == steps[3][1] * own


@pytest.fixture(scope="module")
def branched_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("branched")
    config = _config(imagine={"real_share": 0.25})
    # Compiled bitwise, so that the split over two devices below can be held to it.
    with optimised():  # the `optimized` tests below hold other programs to its bits
        summary = train(config, out, checkpoint_every=1, quiet=True, bitwise=True)
    return config, out, summary


@pytest.mark.optimized
def test_imagined_counts_are_the_played_weights_and_meet_the_ratio(branched_run):
    from ldn_jax.host.run_dir import RunDir

    config, out, _ = branched_run
    trainer = Trainer(config)
    final = RunDir(out).restore_final(jax.eval_shape(trainer.init_batch))
    lines = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    row = config.imagine.branches * config.agent.n_steps  # every imagined row is live
    for seed in range(config.seeds):
        mine = [line for line in lines if line["seed"] == seed]
        imagined = np.diff([0] + [line["imagined_steps"] for line in mine])
        real = np.diff([0] + [line["env_steps"] for line in mine])
        assert (imagined % row == 0).all() and (imagined > 0).all()
        assert (imagined >= config.imagine.ratio * real).all()
        assert (imagined < config.imagine.ratio * real + row).all()
        assert int(final.imagined_steps[0, seed]) == mine[-1]["imagined_steps"]


@pytest.mark.optimized
def test_a_branched_run_resumes_to_the_uninterrupted_run_bitwise(branched_run, tmp_path):
    from ldn_jax.host.training import Interrupted
    from tests.test_resume import StopAfter, _lines

    config, out, _ = branched_run
    with pytest.raises(Interrupted):
        train(config, tmp_path, checkpoint_every=1, quiet=True, stop=StopAfter(1), bitwise=True)
    train(config, tmp_path, checkpoint_every=1, quiet=True, resume=True, bitwise=True)
    assert _lines(tmp_path) == _lines(out)


# -- the config ------------------------------------------------------------------------------


def _build(*argv):
    return flags.build_config(flags.parse_args(list(argv)))


@pytest.mark.parametrize(
    "argv, needle",
    [
        (
            ["--algo", "ppo-model", "--set", "stop.rule=mbpo", "--set", "stop.horizon_min=9",
             "--set", "stop.horizon_max=3"],
            "needs 1 <= horizon_min <= horizon_max, got 9 and 3",
        ),
        (["--algo", "ldn", "--set", "imagine.real_share=1.5"], "real_share must be in [0, 1), got"),
        (["--algo", "ldn", "--set", "imagine.real_share=-0.1"], "real_share must be in [0, 1)"),
        (["--algo", "ppo", "--set", "imagine.start=real"], "ppo imagines none"),
        (["--algo", "a2c", "--set", "imagine.start=real"], "a2c imagines none"),
        (["--algo", "ldn", "--stop", "macura", "--ld", "m0"], "stop 'macura' reads the"),
        (["--algo", "ldn", "--stop", "m2ac", "--ld", "m0"], "stop 'm2ac' reads the disagreement"),
        (["--algo", "ldn", "--set", "model.ld=variance"], "it needs model.probabilistic"),
        (["--algo", "ldn", "--ld", "ensemble", "--set", "model.elites=9"], "elites must be in [1,"),
        (["--algo", "ldn", "--set", "imagine.branches=0"], "branches must be >= 1"),
        (["--algo", "ldn", "--set", "imagine.std=fixed"], "unknown imagine.std 'fixed'"),
        (["--algo", "ldn", "--set", "model.imagined_step=mode"], "unknown imagined_step 'mode'"),
        (["--algo", "ldn", "--set", "model.imagined_step=mean"], "it needs model.probabilistic"),
        (["--algo", "ppo-model", "--set", "imagine.std=real"], "needs branched imagination"),
        (["--algo", "ldn", "--set", "imagine.updates=actor"], "unknown imagine.updates"),
        (
            ["--algo", "ldn", "--preset", "branched", "--env", "cartpole-v1",
             "--set", "imagine.epochs=2"],
            "ldn is of the A2C family",
        ),
        (["--algo", "ppo-model", "--set", "imagine.epochs=2"], "needs imagine.start 'real'"),
        (["--algo", "ppo-model", "--set", "imagine.epochs=-1"], "must be >= 0, got -1"),
        (
            ["--algo", "ppo-model", "--set", "imagine.start_window=100"],
            "needs imagine.start 'real'",
        ),
        (
            ["--algo", "ppo-model", "--preset", "branched", "--set", "imagine.start_window=-1"],
            "start_window must be >= 0, got -1",
        ),
        (
            ["--algo", "ppo-model", "--set", "imagine.updates=critic"],
            "imagine.updates 'critic' needs branched imagination",
        ),
        (
            ["--algo", "ppo-model", "--preset", "branched", "--set", "imagine.actor_step=2"],
            "imagine.actor_step must be in [0, 1], got 2",
        ),
        (
            ["--algo", "ppo-model", "--set", "imagine.actor_step=0.5"],
            "needs imagine.start 'real' and imagine.updates 'all'",
        ),
        (
            ["--algo", "ppo-model", "--preset", "branched",
             "--set", "imagine.updates=critic", "--set", "imagine.actor_step=0.5"],
            "needs imagine.start 'real' and imagine.updates 'all'",
        ),
        (
            ["--algo", "ppo-model", "--preset", "branched", "--env", "cartpole-v1",
             "--set", "imagine.std=real"],
            "a state-independent log std",
        ),
    ],
)  # fmt: skip
def test_bad_branched_settings_are_one_line(argv, needle):
    with pytest.raises(UsageError) as error:
        _build(*argv)
    assert needle in str(error.value) and "\n" not in str(error.value)


def test_macura_defaults_its_estimator_to_the_ensemble():
    config = _build("--algo", "ppo-model", "--stop", "macura", "--set", "imagine.start=real")
    assert config.model.ld == "ensemble" and config.stop_rule == "macura"


@pytest.mark.optimized
def test_a_branched_run_split_over_two_devices_is_the_one_device_run_bitwise(
    branched_run, tmp_path
):
    from tests.test_resume import _lines
    from tests.test_scale import _run

    _, one, _ = branched_run
    two = tmp_path / "two"
    args = ["--config", str(one / "config.json"), "--devices", "2", "--bitwise", "--quiet"]
    result = _run(*args, "--compile-cache", "none", "--out", str(two), devices=2)
    assert result.returncode == 0, result.stderr
    assert json.loads((two / "summary.json").read_text())["devices"] == 2
    assert _lines(two) == _lines(one)


@pytest.mark.parametrize("algo", ["ppo", "ppo-model", "ppo-ldn", "a2c", "a2c-model", "ldn"])
def test_the_branched_preset_gives_its_model_to_model_based_algorithms_only(algo):
    config = validate(from_preset("branched", env="halfcheetah", algo=algo))
    model_based = algo not in ("ppo", "a2c")
    assert (config.imagine.start == "real") == model_based
    assert config.model.probabilistic == model_based
    assert config.schedule == "steps" and config.k == (1.0,)
    # The model-free learner runs with the same constants beside its model-based variants.
    twin = validate(from_preset("branched", env="halfcheetah", algo=algo.split("-")[0]))
    assert config.agent == twin.agent and config.iteration_steps == twin.iteration_steps
    if algo.startswith("ppo"):  # two of the PPO's 64-step rollouts per iteration
        assert config.iteration_steps == 128
    paper = from_preset("paper", env="halfcheetah", algo=algo)
    assert paper.imagine.start == "initial"
    # halfcheetah's PPO is the zoo's under every preset (the task's default); A2C's is not
    assert config.agent == paper.agent
    assert paper.agent.hidden_layers == (2 if algo.startswith("ppo") else 1)


def test_hoppers_branched_preset_trains_the_critic_only_on_imagined_rows():
    """hopper's measured default under `branched`: imagined rows train the critic only, for
    every model-based algorithm; the model-free learner beside them has no model settings."""
    for algo in ("ppo-model", "ppo-ldn", "a2c-model", "ldn"):
        assert validate(from_preset("branched", env="hopper", algo=algo)).imagine.updates == (
            "critic"
        )
        assert validate(from_preset("branched", env="halfcheetah", algo=algo)).imagine.updates == (
            "all"
        )
    assert validate(from_preset("branched", env="hopper", algo="ppo")).imagine.start == ("initial")


def test_explain_names_the_preset_env_and_learner_layer():
    given = {"env": ("halfcheetah", "flag"), "algo": ("ppo", "flag")}
    from ldn_jax.config import explain

    layers = explain("branched", given, "iteration_steps")
    assert layers[-1] == ("preset branched, halfcheetah, ppo", 128)
    assert explain("branched", given, "agent.n_steps")[-1] == ("task halfcheetah", 64)


@pytest.mark.slow
def test_the_branched_preset_solves_inverted_pendulum_sooner_than_ppo(tmp_path):
    """One seed, greedy evaluations after every iteration: the preset's ppo-ldn reaches a
    greedy return of 900 within 25k real steps, and in fewer steps than ppo beside it."""
    steps = {}
    for algo in ("ppo", "ppo-ldn"):
        config = from_preset(
            "branched", env="inverted_pendulum", algo=algo, seeds=1, steps=25_000,
            solved_return=900.0,
        )  # fmt: skip
        train(validate(config), tmp_path / algo, checkpoint_every=0, quiet=True)
        lines = [
            json.loads(x) for x in (tmp_path / algo / "metrics.jsonl").read_text().splitlines()
        ]
        solved = [x["env_steps"] for x in lines if (x.get("greedy_return") or 0) >= 900]
        steps[algo] = solved[0] if solved else math.inf
    assert steps["ppo-ldn"] <= 25_000, steps
    assert steps["ppo-ldn"] < steps["ppo"], steps


def test_the_m0_reading_of_a_probabilistic_ensemble_is_eq3_on_the_drawn_member():
    """`ld` "m0" with `probabilistic`: sigma2 = 1/2 mean((mu_M1 - mu_M0)^2) of the drawn elite's
    mean against its own initial copy; 0 (so P(stop) 1) while M1 is M0."""
    from ldn_jax.imagination import LD_ESTIMATES

    dynamics = _dynamics({**BRANCHED, "ld": "m0"}, 4, 2)
    assert dynamics.ensemble  # a probabilistic model is always an ensemble
    model = dynamics.init(jax.random.key(0))
    obs, action = jax.random.normal(jax.random.key(1), (8, 4)), jnp.ones((8, 2))
    estimate, degree = LD_ESTIMATES["m0"]
    _, sigma2 = estimate(dynamics, model, obs, action, jax.random.key(2))
    assert np.asarray(sigma2).tolist() == [0.0] * 8
    assert np.asarray(degree(sigma2, 1.0)[1]).tolist() == [1.0] * 8
    moved = model.replace(params=jax.tree.map(lambda x: x * 1.5, model.params))
    key = jax.random.key(2)
    _, sigma2 = estimate(dynamics, moved, obs, action, key)
    # The member each row drew, as the estimator draws it (the same key).
    pick = jax.random.randint(jax.random.split(key)[0], (8,), 0, 2)
    member = np.asarray(moved.elites)[np.asarray(pick)]
    stats = dynamics.init_stats()
    for row in range(8):
        params = lambda tree, i=member[row]: jax.tree.map(lambda x: x[i], tree)
        m1, _ = dynamics.predict_gaussian(params(moved.params), stats, obs[row], action[row])
        m0, _ = dynamics.predict_gaussian(params(model.params), stats, obs[row], action[row])
        expected = 0.5 * float(jnp.mean(jnp.square(m1 - m0)))
        assert expected > 1e-4
        assert float(sigma2[row]) == pytest.approx(expected, rel=1e-5)


def test_the_branch_cut_is_its_own_flag_and_horizon_keeps_its_meaning():
    config = _build("--env", "halfcheetah", "--algo", "ppo-ldn", "--preset", "branched")
    assert (config.imagine.cut, config.stop.horizon) == (15, 5)
    config = _build(
        "--env", "halfcheetah", "--algo", "ppo-ldn", "--preset", "branched", "--cut", "7"
    )
    assert config.imagine.cut == 7
    for argv, needle in [
        (["--algo", "ldn", "--cut", "7"], "--cut needs branches"),
        (["--algo", "ppo-model", "--preset", "branched", "--cut", "0"], "cut must be >= 1"),
        (["--algo", "ppo-model", "--preset", "branched", "--stop", "horizon"], "is --cut"),
        (["--algo", "ppo-model", "--preset", "branched", "--horizon", "9"], "needs --stop"),
    ]:
        with pytest.raises(UsageError, match=needle):
            _build(*argv)


def _before_sections(config) -> dict:
    """`config`'s config.json as it was written before `ModelConfig` and `AgentConfig` were
    split: every moved field back in `model` or `agent` under its old name."""
    from ldn_jax.config import ALIASES

    data = config.to_dict()
    for old, new in ALIASES.items():
        (was, key), (now, new_key) = old.split("."), new.split(".")
        data[was][key] = data[now].pop(new_key)
    assert data["imagine"].pop("termination") == "known"  # added since: read as its default
    for section in ("ppo", "stop", "imagine"):
        assert data.pop(section) == {}
    return data


def test_a_config_json_from_before_the_sections_reads_as_the_same_config():
    """Every field that moved to `ppo`, `stop` or `imagine` is read from its old place, and
    its old dotted name still sets it."""
    from ldn_jax.config import Config

    config = from_preset("branched", env="hopper", algo="ppo-ldn", steps=1000, seeds=2)
    old = _before_sections(config)
    assert old["model"]["imagine_start"] == "real" and old["agent"]["epochs"] == 10
    assert Config.from_dict(old) == config
    assert _build("--algo", "ppo", "--set", "agent.epochs=3").ppo.epochs == 3
    assert _build("--algo", "ldn", "--set", "model.stop=oracle").stop.rule == "oracle"


def test_a_run_from_before_the_cut_field_reads_its_horizon_as_the_cut():
    """config.json of a branched run written before `cut` existed: its horizon was the
    branch cut, so it loads as that cut (and a cached run of it is the same config)."""
    from ldn_jax.config import Config

    new = from_preset("branched", env="halfcheetah", algo="ppo-ldn", steps=1000)
    old = _before_sections(new)
    cut = old["model"].pop("cut")
    old["model"] = {**old["model"], "horizon": cut}
    assert old["model"]["horizon"] == 15
    assert Config.from_dict(old) == new
    initial = _before_sections(from_preset("paper", env="cartpole-v1", algo="ldn"))
    initial["model"].pop("cut")
    assert Config.from_dict(initial).imagine.cut == ImagineConfig.cut


def test_the_fit_until_stalled_stops_on_the_held_out_error_and_keeps_each_members_best():
    """MBPO's fit (`Dynamics.fit_until_stalled`): epochs until no member's held-out error has
    fallen by 1% for 5 epochs in a row, each member back at its best."""
    from ldn_jax.dynamics import HOLDOUT_BATCH, EarlyStop

    model = {**BRANCHED, "hidden": 32, "updates": 25, "lr": 3e-3, "normalize": True}
    dynamics = _dynamics(model, 2, 1)
    k = jax.random.split(jax.random.key(0), 3)
    obs = jax.random.normal(k[0], (500, 2))
    action = jax.random.uniform(k[1], (500, 1), minval=-1.0, maxval=1.0)
    batch = Transitions(
        obs=obs,
        action=action,
        next_obs=obs + 0.1 * action + 0.01 * jax.random.normal(k[2], (500, 2)),
        reward=obs.sum(axis=1),
    )
    buffer = buffer_add(buffer_init(512, 2, 1), batch, jnp.ones(500, bool))
    state = dynamics.init(jax.random.key(1))
    fit = jax.jit(lambda s, key, stop: dynamics.fit_until_stalled(s, buffer, key, stop),
                  static_argnums=2)  # fmt: skip
    once, _, epochs = fit(state, jax.random.key(2), EarlyStop(max_epochs=1))
    assert int(epochs) == 1
    fitted, loss, epochs = fit(state, jax.random.key(2), EarlyStop(max_epochs=400))
    # it stopped by itself, after at least the first epoch's gain and 6 without one
    assert 7 <= int(epochs) < 400 and np.isfinite(float(loss))
    # the elites' held-out error: lower than after one epoch, and what the state now scores
    held = buffer_sample_split(
        buffer, jax.random.fold_in(jax.random.key(2), 1), HOLDOUT_BATCH, True
    )
    errors = jax.vmap(dynamics.squared_error, (0, None, None))(fitted.params, held, fitted.stats)
    elite = np.asarray(errors)[np.asarray(fitted.elites)]
    assert float(fitted.error_scale) == pytest.approx(elite.mean(), rel=1e-5)
    first = jax.vmap(dynamics.squared_error, (0, None, None))(once.params, held, once.stats)
    assert elite.mean() < 0.5 * float(np.asarray(first).mean())
    # a cap of steps (`fit.updates` under early_stop) ends it at the first epoch that
    # reaches the cap, before it would have stalled
    per_epoch = -(-450 // dynamics.fitting.batch_size)  # 500 rows, one slot in 10 held out
    _, _, capped = fit(
        state, jax.random.key(2), EarlyStop(max_epochs=400, max_steps=2 * per_epoch + 1)
    )
    assert int(capped) == 3 < int(epochs)
