"""The ensemble learning degree (`--ld ensemble`): its maths, the vmapped fit, imagination with
agreeing members, an end-to-end run, and the config and CLI plumbing."""

import json
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ldn_jax import load_policy
from ldn_jax.buffer import buffer_add, buffer_init
from ldn_jax.config import (
    AgentConfig,
    Config,
    FitConfig,
    ModelConfig,
    StopConfig,
    from_preset,
    validate,
)
from ldn_jax.dynamics import Dynamics, ModelState
from ldn_jax.host import checkpoint
from ldn_jax.host.run_dir import FINAL as FINAL_CHECKPOINT
from ldn_jax.host.run_dir import read_config as read_run_config
from ldn_jax.host.training import train
from ldn_jax.imagination import EnvFacts, model_world, stop_rule
from ldn_jax.learners.a2c import A2C
from ldn_jax.learning_degree import (
    ERROR_FLOOR,
    disagreement,
    ensemble_learning_degree,
    ensemble_mean,
    ensemble_stop_probability,
    relative_disagreement,
)
from ldn_jax.rollout import Player, play_episodes
from ldn_jax.trainer import Trainer
from tests.test_core import _cartpole_transitions

ROOT = Path(__file__).resolve().parents[1]
RUN = [sys.executable, str(ROOT / "experiments" / "run.py")]


# -- (a) the estimator's maths ---------------------------------------------------------------


def test_ensemble_learning_degree_hand_computed():
    # Two members, two outputs: mean [1, 1], variance [1, 1] -> d = 1/2 mean([1, 1]) = 0.5.
    members = jnp.array([[0.0, 0.0], [2.0, 2.0]])
    d = disagreement(members)
    assert float(d) == 0.5
    np.testing.assert_array_equal(np.asarray(ensemble_mean(members)), [1.0, 1.0])
    d_rel = relative_disagreement(d, 0.25)  # in units of the fit MSE: 2
    assert float(d_rel) == 2.0
    assert float(ensemble_learning_degree(d_rel)) == pytest.approx(2 / (1 + np.exp(2)), rel=1e-6)
    assert float(ensemble_stop_probability(d_rel)) == pytest.approx(np.tanh(1.0), rel=1e-6)
    # Agreement: LD exactly 1, P(stop) exactly 0; a zero error scale is floored, not divided by.
    assert (
        float(ensemble_learning_degree(0.0)) == 1.0 and float(ensemble_stop_probability(0.0)) == 0
    )
    assert float(relative_disagreement(1e-12, 0.0)) == pytest.approx(1e-12 / ERROR_FLOOR)
    # Large disagreement: LD -> 0, P(stop) -> 1.
    assert float(ensemble_learning_degree(50.0)) < 1e-20
    assert float(ensemble_stop_probability(50.0)) == 1.0


def test_ensemble_ld_monotone_in_k_and_stop_is_one_minus_ld_without_cancellation():
    d_rel = jnp.linspace(0.01, 8.0, 200)
    lds = [np.asarray(ensemble_learning_degree(d_rel, k)) for k in (0.5, 1.0, 2.0)]
    assert (lds[0] > lds[1]).all() and (lds[1] > lds[2]).all()  # larger K, stops sooner
    assert all((np.diff(ld) < 0).all() for ld in lds)  # falls as members disagree
    for k, ld in zip((0.5, 1.0, 2.0), lds, strict=True):
        np.testing.assert_allclose(np.asarray(ensemble_stop_probability(d_rel, k)), 1 - ld, 1e-5)
    # 1 - 2 sigmoid(-x) rounds to 0 here; tanh keeps it.
    assert float(ensemble_stop_probability(1e-8)) == pytest.approx(5e-9, rel=1e-6)


def test_disagreement_is_exactly_zero_for_equal_members():
    # A plain mean of 3 or 5 equal float32 values need not round back to them: np.var of the
    # stack would be tiny but nonzero for many of these.
    x = jax.random.normal(jax.random.key(0), (1000, 5)) * 1e3
    for members in (3, 5):
        stack = jnp.broadcast_to(x, (members, *x.shape))
        np.testing.assert_array_equal(np.asarray(disagreement(stack)), 0.0)
        np.testing.assert_array_equal(np.asarray(ensemble_mean(stack)), np.asarray(x))


# -- (b) members: distinct initialisations, distinct fits, vmapped == one by one ------------


def _buffer(n=2048):
    buffer = buffer_init(n, 4, 2)
    return buffer_add(buffer, _cartpole_transitions(jax.random.key(1), n), jnp.ones(n, bool))


def _member(tree, i):
    return jax.tree.map(lambda x: x[i], tree)


def test_members_start_apart_and_m0_copies_them():
    state = Dynamics(ModelConfig(ld="ensemble", ensemble=3), 4, 2).init(jax.random.key(0))
    leaves = jax.tree.leaves(state.params)
    assert all(leaf.shape[0] == 3 for leaf in leaves)
    weights = [leaf for leaf in leaves if leaf.ndim == 3]  # biases start at zero for all
    assert len(weights) == 4  # two layers in each of the two nets
    for leaf in weights:
        for i, j in ((0, 1), (0, 2), (1, 2)):
            assert not np.array_equal(leaf[i], leaf[j])
    for a, b in zip(jax.tree.leaves(state.params), jax.tree.leaves(state.frozen), strict=True):
        np.testing.assert_array_equal(a, b)
    assert float(state.error_scale) == 1.0


@pytest.mark.optimized
def test_vmapped_fit_equals_each_member_fitted_alone():
    members, updates = 3, 20
    fit = FitConfig(updates=updates)
    ensemble = Dynamics(ModelConfig(ld="ensemble", ensemble=members, normalize=True), 4, 2, fit=fit)
    single = Dynamics(ModelConfig(normalize=True), 4, 2, fit=fit)
    state, buffer, key = ensemble.init(jax.random.key(0)), _buffer(), jax.random.key(5)
    fitted, loss = jax.jit(ensemble.fit)(state, buffer, key)
    losses = []
    for i, member_key in enumerate(jax.random.split(key, members)):
        alone = ModelState(
            params=_member(state.params, i),
            frozen=_member(state.frozen, i),
            opt_state=_member(state.opt_state, i),
            stats=state.stats,
        )
        alone, member_loss = jax.jit(single.fit)(alone, buffer, member_key)
        losses.append(float(member_loss))
        # Equal to float32 rounding: batched matmuls round unlike unbatched ones.
        for a, b in zip(
            jax.tree.leaves(_member(fitted.params, i)), jax.tree.leaves(alone.params), strict=True
        ):
            np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)
    assert float(loss) == pytest.approx(np.mean(losses), rel=1e-5)
    assert float(fitted.error_scale) == float(loss)


def test_members_fit_on_their_own_minibatches():
    # Members started equal stay equal only if they saw the same minibatches.
    dynamics = Dynamics(ModelConfig(ld="ensemble", ensemble=3), 4, 2, fit=FitConfig(updates=10))
    state = dynamics.init(jax.random.key(0))
    same = jax.tree.map(lambda p: jnp.broadcast_to(p[:1], p.shape), state.params)
    state = state.replace(params=same)  # Adam states start at zero for every member anyway
    fitted, _ = jax.jit(dynamics.fit)(state, _buffer(), jax.random.key(5))
    for leaf in jax.tree.leaves(fitted.params):
        assert not np.array_equal(leaf[0], leaf[1]) and not np.array_equal(leaf[1], leaf[2])


# -- (c) imagination -------------------------------------------------------------------------


def _world(members_equal: bool, ld_stop: bool, error_scale: float):
    dynamics = Dynamics(ModelConfig(ld="ensemble", ensemble=5), obs_size=4, action_size=2)
    model = dynamics.init(jax.random.key(0))
    if members_equal:
        model = model.replace(
            params=jax.tree.map(lambda p: jnp.broadcast_to(p[:1], p.shape), model.params)
        )
    model = model.replace(error_scale=jnp.float32(error_scale))
    never_terminal = lambda obs: jnp.zeros(obs.shape[:-1], bool)
    encode = lambda a: jax.nn.one_hot(a, 2)
    gain = jnp.float32(1.0)
    world = model_world(dynamics, model, EnvFacts(never_terminal, encode), gain, _rule(ld_stop))
    return dynamics, model, world


def _one_step(world, workers=256):
    obs = jax.random.uniform(jax.random.key(6), (workers, 4), minval=-0.05, maxval=0.05)
    action = jnp.arange(workers) % 2
    alive = jnp.ones(workers, bool)
    return obs, action, jax.jit(world)(jax.random.key(7), None, obs, action, alive)


def test_equal_members_never_stop_and_step_as_one_model():
    # Even with a tiny error scale: zero disagreement is LD 1, P(stop) 0, at every step.
    dynamics, model, world = _world(members_equal=True, ld_stop=True, error_scale=1e-6)
    learner = A2C(AgentConfig(), obs_size=4, action_spec=2)
    obs = jax.random.uniform(jax.random.key(2), (64, 4), minval=-0.05, maxval=0.05)
    _, episodes = jax.jit(play_episodes, static_argnums=2)(
        jax.random.key(3), learner.init(jax.random.key(4)), Player(learner, world, 50), obs, None
    )
    np.testing.assert_array_equal(np.asarray(episodes.lengths), 50)
    np.testing.assert_array_equal(np.asarray(episodes.extras["ld"]), 1.0)
    obs, action, (next_obs, _, reward, *_) = _one_step(world)
    one = dynamics.predict_members(model.params, model.stats, obs, jax.nn.one_hot(action, 2))
    # To rounding: the world is one compiled program, the reference eager ops.
    np.testing.assert_allclose(np.asarray(next_obs), np.asarray(one[0][0]), atol=1e-7)
    np.testing.assert_allclose(np.asarray(reward), np.asarray(one[1][0]), atol=1e-7)


def test_disagreeing_members_stop_unless_ld_stop_is_off():
    # Untrained members disagree by ~5e-3; against an error scale of 1e-4 that is d_rel > 10.
    for ld_stop in (True, False):
        _, _, world = _world(members_equal=False, ld_stop=ld_stop, error_scale=1e-4)
        *_, stop, extras = _one_step(world)[2]
        assert np.asarray(extras["ld"]).max() < 0.01
        # a2c-model / ppo-model: the mean prediction, no LD stop.
        assert np.asarray(stop).all() if ld_stop else not np.asarray(stop).any()


# -- config ----------------------------------------------------------------------------------


def test_config_round_trips_and_old_configs_load_as_m0():
    config = from_preset("paper", env="cartpole-v0", model={"ld": "ensemble", "ensemble": 3})
    data = json.loads(json.dumps(config.to_dict()))
    assert Config.from_dict(data) == config
    assert data["model"]["ld"] == "ensemble" and data["model"]["ensemble"] == 3
    del data["model"]["ld"], data["model"]["ensemble"]  # a config.json from before the option
    old = Config.from_dict(data).model
    assert old.ld == "m0" and old.ensemble == 5


@pytest.mark.parametrize(
    ("model", "needle"),
    [({"ld": "bayes"}, "unknown ld 'bayes'; valid: m0, ensemble"), ({"ensemble": 1}, ">= 2")],
)
def test_bad_ld_config_is_one_line(model, needle):
    with pytest.raises(ValueError, match=needle):
        validate(from_preset("paper", env="cartpole-v0", model={"ld": "ensemble", **model}))


# -- (d, e) an end-to-end run from the CLI, its twin in-process, checkpoints and resume ------

ARGS = ["--env", "cartpole-v0", "--algo", "ldn", "--seeds", "2", "--k", "1", "--episodes", "16"]
ARGS += ["--workers", "4", "--chunk", "2", "--checkpoint-every", "0", "--quiet"]


@pytest.fixture(scope="module")
def ensemble_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("ensemble") / "run"
    flags = ["--ld", "ensemble", "--ensemble-size", "3", "--out", str(out)]
    result = subprocess.run([*RUN, *ARGS, *flags], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    return out


def _metric_lines(run_dir: Path) -> list[dict]:
    lines = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    for line in lines:
        line.pop("wall_seconds")
    return lines


def test_ensemble_run_is_finite_deterministic_and_loads(ensemble_run, tmp_path):
    config = read_run_config(ensemble_run)
    assert config.model.ld == "ensemble" and config.model.ensemble == 3
    first = _metric_lines(ensemble_run)
    assert len(first) == 2 * 4  # seeds x iterations
    for line in first:
        assert line["imagined_steps"] > 0 and 0 < line["ld_mean"] <= 1
        assert all(v is not None and np.isfinite(v) for v in line["losses"].values()), line
    assert json.loads((ensemble_run / "summary.json").read_text())["runs"][0]["diverged"] is None
    # The same config again, in this process: the same bits.
    train(config, tmp_path, checkpoint_every=0, quiet=True)
    assert _metric_lines(tmp_path) == first
    # The checkpoint holds the members stacked [K, S, E, ...], M0 copies untouched.
    trainer = Trainer(config)
    initial = trainer.init_batch()
    final = checkpoint.restore(
        ensemble_run / "checkpoints" / FINAL_CHECKPOINT, jax.eval_shape(trainer.init_batch)
    )
    for leaf in jax.tree.leaves(final.model.params):
        assert leaf.shape[:3] == (1, 2, 3)
    leaves = lambda tree: jax.tree.leaves(tree.model.frozen)
    for a, b in zip(leaves(final), leaves(initial), strict=True):
        np.testing.assert_array_equal(a, b)
    assert np.isfinite(final.model.error_scale).all() and (final.model.error_scale != 1).all()
    act = load_policy(ensemble_run, seed=1)
    assert act(np.array([0.01, 0.0, 0.02, 0.1], np.float32)) in (0, 1)


@pytest.mark.parametrize("flag", [["--ld", "m0"], ["--ensemble-size", "4"]])
def test_resume_refuses_a_different_estimator(ensemble_run, flag):
    result = subprocess.run(
        [*RUN, "--resume", str(ensemble_run), *flag], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr
    assert "does not match the run being resumed" in result.stderr


def _rule(ld_stop: bool):
    """The LD draw (ldn) or no stop (a2c-model)."""
    return stop_rule(StopConfig(), "ld" if ld_stop else "none")
