"""The stopping rules of imagined episodes (`--stop`): a fixed horizon, the M2AC-style mask,
the oracle on the true one-step error, and the model's action encodings, on hand-made worlds
and numbers; the CLI's combinations of rule and flags."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ldn_jax.config import AgentConfig, ModelConfig, StopConfig, from_preset, validate
from ldn_jax.dynamics import Dynamics
from ldn_jax.host import flags
from ldn_jax.host.settings import UsageError
from ldn_jax.imagination import (
    EnvFacts,
    imagined_steps_limit,
    m2ac_kept,
    model_world,
    oracle_error,
    stop_rule,
)
from ldn_jax.learners.a2c import A2C
from ldn_jax.rollout import Player, play_episodes
from ldn_jax.stages.imagine import world_of
from ldn_jax.trainer import Trainer

NEVER = lambda obs: jnp.zeros(obs.shape[:-1], bool)
ENCODE = lambda a: jax.nn.one_hot(a, 2)


NO_STOP = StopConfig()


def _play(config: ModelConfig, rule, workers=8, max_steps=50, stop=NO_STOP):
    """Imagined episodes of `workers` workers in an untrained model that never predicts
    termination, under `rule`, with the rule's step limit."""
    dynamics = Dynamics(config, obs_size=4, action_size=2)
    model = dynamics.init(jax.random.key(0))
    if config.ld == "ensemble":
        model = model.replace(error_scale=jnp.float32(1e-4))
    learner = A2C(AgentConfig(), obs_size=4, action_spec=2)
    world = model_world(dynamics, model, EnvFacts(NEVER, ENCODE), jnp.float32(1.0), rule)
    obs = jax.random.uniform(jax.random.key(2), (workers, 4), minval=-0.05, maxval=0.05)
    limit = imagined_steps_limit(stop, stop.rule or "none", max_steps)
    _, episodes = jax.jit(play_episodes, static_argnums=2)(
        jax.random.key(3), learner.init(jax.random.key(4)), Player(learner, world, limit), obs, None
    )
    return dynamics, model, episodes


def test_a_fixed_horizon_stops_exactly_at_h_steps():
    for h in (1, 5, 25):
        stop = StopConfig(rule="horizon", horizon=h)
        _, _, episodes = _play(ModelConfig(), stop_rule(stop, "horizon"), stop=stop)
        np.testing.assert_array_equal(np.asarray(episodes.lengths), h)
        done = np.asarray(episodes.steps.done)
        assert done[h - 1].all() and not np.asarray(episodes.steps.terminated).any()
    assert imagined_steps_limit(StopConfig(horizon=25), "horizon", 10) == 10  # the env's
    assert imagined_steps_limit(StopConfig(horizon=5), "ld", 200) == 200


def test_the_m2ac_mask_keeps_the_stated_share_of_running_rollouts():
    score = jnp.array([0.3, 0.1, 0.5, 0.2, 0.9, 0.4, 0.0, 0.6, 0.7, 0.8])
    alive = jnp.ones(10, bool)
    kept = np.asarray(m2ac_kept(score, alive, 0.3))
    np.testing.assert_array_equal(np.flatnonzero(kept), [1, 3, 6])  # the 3 lowest of 10
    dead = alive.at[jnp.array([1, 6])].set(False)  # 8 running: 0.5 of them is 4
    np.testing.assert_array_equal(np.flatnonzero(m2ac_kept(score, dead, 0.5)), [0, 2, 3, 5])
    # nearest whole count, halves down: 5 running x 0.5 keeps 2; 1 x 0.5 keeps none
    assert int(m2ac_kept(score, alive.at[5:].set(False), 0.5).sum()) == 2
    assert int(m2ac_kept(score, alive.at[1:].set(False), 0.5).sum()) == 0
    assert int(m2ac_kept(score, alive, 1.0).sum()) == 10
    ties = m2ac_kept(jnp.zeros(4), jnp.ones(4, bool), 0.5)
    np.testing.assert_array_equal(np.asarray(ties), [True, True, False, False])


def test_m2ac_rollouts_halve_each_step_in_a_world_of_disagreeing_members():
    config = ModelConfig(ld="ensemble")
    rule = stop_rule(StopConfig(rule="m2ac", m2ac_keep=0.5), "m2ac")
    _, _, episodes = _play(config, rule, workers=16)
    running = np.asarray(episodes.steps.weight).sum(axis=1)
    np.testing.assert_array_equal(running[:6], [16, 8, 4, 2, 1, 0])
    assert running[6:].sum() == 0


def test_the_oracle_never_stops_on_an_exact_model_and_stops_a_wrong_one_at_once():
    config, stop = ModelConfig(), StopConfig(rule="oracle", oracle_error=0.01)
    dynamics = Dynamics(config, obs_size=4, action_size=2)
    model = dynamics.init(jax.random.key(0))
    predict = lambda obs, action: dynamics.predict(model.params, obs, ENCODE(action))[0]
    exact = lambda key, obs, action: predict(obs, action)  # the "real env" is the model
    _, _, episodes = _play(config, stop_rule(stop, "oracle", exact))
    np.testing.assert_array_equal(np.asarray(episodes.lengths), 50)  # the step limit only
    for offset, length in ((0.004, 50), (0.02, 1)):  # ||(c, c, c, c)|| = 2c against 0.01
        wrong = lambda key, obs, action, c=offset: predict(obs, action) + c
        _, _, episodes = _play(config, stop_rule(stop, "oracle", wrong))
        np.testing.assert_array_equal(np.asarray(episodes.lengths), length)
    assert float(oracle_error(jnp.zeros(4), jnp.full(4, 0.5))) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="needs the real env"):
        stop_rule(stop, "oracle")


def test_the_oracle_steps_the_real_cartpole_from_imagined_states():
    trainer = Trainer(from_preset("paper", env="cartpole-v1", algo="ldn", seeds=1))
    obs = jnp.array([[0.0, 0.0, 0.0, 0.0], [0.01, 0.1, -0.02, 0.3]])
    action = jnp.array([0, 1])
    truth = trainer.parts.real.true_next(jax.random.key(0), obs, action)
    physics = jax.vmap(lambda o, a: trainer.env.step(
        jax.random.key(0), trainer.env.from_observation(o, trainer.env_params), a,
        trainer.env_params)[0])(obs, action)  # fmt: skip
    np.testing.assert_array_equal(np.asarray(truth), np.asarray(physics))
    assert float(truth[0, 1]) < 0 < float(truth[1, 1])  # force -10 slows, +10 speeds the cart


def test_a_true_world_steps_the_real_env_where_the_model_would_and_still_reads_the_model():
    """`model.world` "true": each imagined step is the real CartPole's from the imagined
    state (next observation, reward, termination), while the learning degree is still the
    model's; the default world steps the untrained model, which is far off. The hybrids take
    the real termination and either the real reward or the real next observation."""
    obs = jnp.array([[0.0, 0.0, 0.0, 0.0], [0.01, 0.1, -0.02, 0.3], [0.0, 0.0, 0.2, 1.0]])
    action = jnp.array([0, 1, 1])
    key, alive = jax.random.key(1), jnp.ones(3, bool)
    steps = {}
    for world in ("model", "true", "true-reward", "true-state"):
        config = from_preset(
            "paper", env="cartpole-v1", algo="ldn", seeds=1, model={"world": world}
        )
        trainer = Trainer(config)
        state = jax.tree.map(lambda x: x[0, 0], trainer.init_batch())
        step = world_of(trainer.parts, state, jnp.float32(1.0))
        steps[world] = step(key, None, obs, action, alive)
    next_obs, _, reward, terminated, _, extras = steps["true"]
    truth, true_reward, true_term = trainer.parts.real.true_step(jax.random.key(9), obs, action)
    np.testing.assert_array_equal(np.asarray(next_obs), np.asarray(truth))
    np.testing.assert_array_equal(np.asarray(reward), np.asarray(true_reward))
    np.testing.assert_array_equal(np.asarray(terminated), [False, False, True])
    np.testing.assert_array_equal(np.asarray(terminated), np.asarray(true_term))
    np.testing.assert_array_equal(np.asarray(extras["ld"]), np.asarray(steps["model"][5]["ld"]))
    assert np.abs(np.asarray(steps["model"][0]) - np.asarray(truth)).max() > 1e-3
    # "true-reward": the model's next observation, the real reward and termination.
    np.testing.assert_array_equal(
        np.asarray(steps["true-reward"][0]), np.asarray(steps["model"][0])
    )
    np.testing.assert_array_equal(np.asarray(steps["true-reward"][2]), np.asarray(true_reward))
    np.testing.assert_array_equal(np.asarray(steps["true-reward"][3]), [False, False, True])
    # "true-state": the real next observation and termination, the model's reward.
    np.testing.assert_array_equal(np.asarray(steps["true-state"][0]), np.asarray(truth))
    np.testing.assert_array_equal(np.asarray(steps["true-state"][2]), np.asarray(steps["model"][2]))
    assert np.abs(np.asarray(steps["model"][2]) - np.asarray(true_reward)).max() > 1e-3
    np.testing.assert_array_equal(np.asarray(steps["true-state"][3]), [False, False, True])


@pytest.mark.parametrize(
    "encoding, expected",
    [
        ("one-hot", [[1, 0, 0, 0, 0], [0, 0, 0, 0, 1]]),
        ("index", [[0], [4]]),
        ("force", [[-10], [10]]),
    ],
)
def test_the_action_encodings(encoding, expected):
    trainer = Trainer(
        from_preset(
            "paper", env="cartpole-v2", algo="a2c-model", model={"action_encoding": encoding}
        )
    )
    encoded = trainer.model_action(jnp.array([0, 4]))
    np.testing.assert_array_equal(np.asarray(encoded), expected)
    assert trainer.model_action_size == len(expected[0])
    assert trainer.dynamics.action_size == len(expected[0])


def build(*argv):
    return flags.build_config(flags.parse_args(list(argv)))


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--algo", "a2c", "--stop", "horizon"], "a2c imagines none; use --algo a2c-model or ldn"),
        (["--algo", "ppo", "--stop", "m2ac"], "use --algo ppo-model or ppo-ldn"),
        (["--algo", "ldn", "--stop", "none"], "ldn with stop 'none' is a2c-model"),
        (["--algo", "a2c-model", "--stop", "ld"], "use --algo ldn"),
        (["--algo", "ppo-model", "--stop", "ld"], "use --algo ppo-ldn"),
        (["--algo", "ldn", "--horizon", "3"], "--horizon needs --stop horizon"),
        (["--algo", "ldn", "--m2ac-keep", "0.3"], "--m2ac-keep needs --stop m2ac"),
        (["--stop", "ld", "--oracle-error", "1"], "--oracle-error needs --stop oracle"),
        (["--algo", "ldn", "--stop", "m2ac", "--ld", "m0"], "it needs ld 'ensemble'"),
        (["--algo", "ldn", "--stop", "horizon", "--horizon", "0"], "horizon must be >= 1"),
        (["--algo", "ldn", "--stop", "m2ac", "--m2ac-keep", "0"], "m2ac_keep must be in (0, 1]"),
        (["--algo", "ldn", "--stop", "oracle", "--oracle-error", "-1"], "oracle_error must be > 0"),
        (
            ["--env", "ant", "--algo", "ldn", "--stop", "oracle"],
            "ant's observation is not its whole state",
        ),
        (
            ["--env", "reacher", "--algo", "ldn", "--set", "model.world=true"],
            "world 'true' steps the real env from imagined observations, and reacher's",
        ),
        (
            ["--env", "ant", "--algo", "ldn", "--set", "model.world=true-reward"],
            "world 'true-reward' steps the real env from imagined observations, and ant's",
        ),
        (["--algo", "ldn", "--set", "model.world=perfect"], "unknown world 'perfect'"),
        (["--algo", "ldn", "--set", "model.value_loss=-1"], "value_loss must be >= 0, got -1"),
        (
            ["--env", "inverted_pendulum", "--algo", "ldn", "--action-encoding", "force"],
            "action_encoding is for discrete actions",
        ),
    ],
)  # fmt: skip
def test_bad_combinations_of_rule_and_flags_are_one_line(argv, needle):
    with pytest.raises(UsageError, match=None) as error:
        build(*argv)
    assert needle in str(error.value) and "\n" not in str(error.value)


def test_each_rule_alone_builds_with_its_documented_defaults():
    for algo, rule, uses_k in (
        ("ldn", None, True),
        ("a2c-model", None, False),
        ("ldn", "ld", True),
        ("ldn", "m2ac", False),
        ("ldn", "horizon", False),
        ("a2c-model", "oracle", False),
        ("ppo-model", "horizon", False),
    ):
        config = build("--algo", algo, *(["--stop", rule] if rule else []))
        expected = rule or ("ld" if algo == "ldn" else "none")
        assert config.stop_rule == expected and config.uses_k == uses_k
        assert len(config.k) == (3 if uses_k else 1)  # K matters to the LD draw only
    assert build("--stop", "m2ac").model.ld == "ensemble"  # M2AC ranks by disagreement
    assert build("--stop", "m2ac", "--ensemble-size", "3").model.ensemble == 3
    assert build("--stop", "horizon", "--horizon", "25").stop.horizon == 25
    assert from_preset("paper", algo="a2c").stop_rule is None
    validate(from_preset("paper", algo="ldn", stop={"rule": "oracle"}))


@pytest.mark.slow  # the paper smoke (test_paper) trains each rule too, in the default suite
@pytest.mark.parametrize("rule", ["m2ac", "horizon", "oracle"])
def test_each_rule_trains_and_counts_its_imagined_steps(rule):
    """A chunk of training under each new rule: the imagined steps counted are those
    the rule let through (horizon: at most h a episode; m2ac: 8 + 4 + 2 + 1 of 8 workers)."""
    config = validate(
        from_preset(
            "paper", env="cartpole-v1", algo="ldn", seeds=1, workers=8, episodes=16,
            chunk_iterations=2, stop={"rule": rule, "horizon": 3},
        )
    )  # fmt: skip
    trainer = Trainer(config)
    states, metrics = trainer.batched_chunk()(trainer.init_batch(), trainer.point_values())
    imagined = np.asarray(metrics["imagined_steps"])[0, 0]
    per_iteration = np.diff(imagined, prepend=0)
    assert (per_iteration > 0).all()
    length = np.asarray(metrics["imagined_length"])[0, 0]
    if rule == "horizon":
        assert (per_iteration <= 3 * 8).all() and (length <= 3).all()
    if rule == "m2ac":
        assert (per_iteration <= 8 + 4 + 2 + 1).all()
    assert int(states.imagined_steps[0, 0]) == int(imagined[-1])


def test_a_penalty_takes_its_weight_times_the_ensembles_disagreement_from_each_reward():
    """`model.penalty` (MOPO's pessimism): the imagined reward less the weight times the
    step's relative disagreement of the members, computed here from their predictions."""
    obs = jnp.array([[0.0, 0.0, 0.0, 0.0], [0.01, 0.1, -0.02, 0.3], [0.0, 0.0, 0.2, 1.0]])
    action = jnp.array([0, 1, 1])
    key, alive = jax.random.key(1), jnp.ones(3, bool)
    steps = {}
    for penalty in (0.0, 2.5):
        model = {"ld": "ensemble", "ensemble": 3, "penalty": penalty}
        model.update(ld_scale=10.0, ld_window=3)  # the penalty reads the step before them
        config = from_preset("paper", env="cartpole-v1", algo="ldn", seeds=1, model=model)
        trainer = Trainer(validate(config))
        state = jax.tree.map(lambda x: x[0, 0], trainer.init_batch())
        state = state.replace(model=state.model.replace(error_scale=jnp.float32(0.01)))
        world = world_of(trainer.parts, state, jnp.float32(1.0))
        history = jnp.full((3, 2), 5.0)  # earlier steps' deviations in the window
        steps[penalty] = world(key, history, obs, action, alive)
    dynamics, model = trainer.dynamics, state.model
    members = jnp.concatenate(
        [m[..., None] if m.ndim == 2 else m for m in
         dynamics.predict_members(model.params, model.stats, obs, ENCODE(action))], axis=-1
    )  # fmt: skip
    centred = members - members.mean(axis=0)
    d_rel = 0.5 * np.mean(np.square(np.asarray(centred)), axis=(0, 2)) / 0.01
    assert d_rel.min() > 0
    np.testing.assert_allclose(
        np.asarray(steps[0.0][2]) - np.asarray(steps[2.5][2]), 2.5 * d_rel, rtol=1e-4
    )
    np.testing.assert_array_equal(np.asarray(steps[0.0][0]), np.asarray(steps[2.5][0]))
    ensemble = {"ld": "ensemble", "ensemble": 3}
    for model, needle in [
        ({**ensemble, "penalty": -1.0}, "penalty must be >= 0"),
        ({"penalty": 1.0}, "penalty reads an ensemble's uncertainty"),  # ld "m0"
        ({**ensemble, "penalty": 1.0, "world": "true"}, "world 'true' takes the real env's"),
    ]:
        with pytest.raises(ValueError, match=needle):
            validate(from_preset("paper", env="cartpole-v1", algo="ldn", model=model))
