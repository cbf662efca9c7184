"""Imagined episodes: the agent acts in M1, and a stopping rule decides when to stop.

Predicted termination (the env's own termination test on M1's predicted observation) ends
an imagined episode as terminal: no bootstrap. A stopping rule (`StopConfig.rule`: the
learning-degree draw of MBRL-LDN, an M2AC-style mask, an oracle; `STOP_RULES`) ends it as a
truncation: the critic bootstraps, since the episode itself had not ended. A fixed horizon
is the episode's step limit (`imagined_steps_limit`).

With an ensemble (`ModelConfig.ld = "ensemble"`) the world steps the members' mean prediction
and the LD comes from their disagreement instead of from M1 vs M0. A probabilistic ensemble
(`ModelConfig.probabilistic`) steps a sample of one elite member drawn at random per rollout
and step; its LD reads the disagreement of the elites' means ("ensemble") or the drawn
member's own predicted variance ("variance").
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import jax
import jax.numpy as jnp
from flax import struct

from ldn_jax.config import LD_ESTIMATORS, STOP_RULES, StopConfig
from ldn_jax.dynamics import Dynamics, ModelState
from ldn_jax.learning_degree import (
    REDUCE,
    deviation,
    disagreement,
    ensemble_learning_degree,
    ensemble_mean,
    ensemble_stop_probability,
    learning_degree,
    relative_disagreement,
    stop_draw,
    stop_probability,
    windowed,
)
from ldn_jax.rollout import WorldStep

Array = jax.Array


@dataclass(frozen=True)
class EnvFacts:
    """What an imagined world takes from the real env."""

    is_terminal: Callable
    """`obs -> terminated`: the env's own test (or the model's learned one,
    `ImagineConfig.termination`), applied to predicted observations."""
    model_action: Callable
    """Encodes the env action as the model takes it (one-hot, or the clipped vector)."""
    env_reward: Callable | None = None
    """`(obs, action, next_obs) -> reward`, if not None, replaces the model's reward (the LD
    still reads the models' whole output)."""
    true_step: Callable | None = None
    """`(key, obs, action) -> (next_obs, reward, terminated)`, if not None: the real env
    stepped from the imagined observations (`ModelConfig.world` other than "model")."""
    true_state: bool = True
    """With `true_step`: its next observation replaces the model's ("true", "true-state")."""
    true_reward: bool = True
    """With `true_step`: its reward replaces the model's ("true", "true-reward")."""


def model_world(
    dynamics: Dynamics, model: ModelState, facts: EnvFacts, gain: Array, stop: StopRule
) -> WorldStep:
    """A world that steps M1 (an ensemble: its members' mean prediction). Its extras carry
    each step's learning degree `ld`.

    `facts.true_step`, if not None, gives each step in place of the model's prediction,
    which the learning degree and `stop` still read. Its termination always replaces the
    model's; `true_state` False keeps the model's next observation ("true-reward"),
    `true_reward` False the model's reward ("true-state"; with `env_reward`, the exact
    reward of the model's predicted transition).

    The model's `penalty` (`ModelConfig.penalty`) is subtracted from each step's reward times
    the estimator's statistic before scale and window (MOPO's pessimism).

    The deviation of eq. 3 is taken in the
    model's normalised output space (the raw one when normalisation is off), so no
    observation dimension dominates it by its units; so is an ensemble's disagreement.
    `stop` is the stopping rule (`stop_rule`). A prediction outside the real data's box
    (`ModelConfig.support`) stops the episode as a rule does; extras then carry `outside`,
    the steps it stopped that way.

    The world's state is the window of the last `ld_window - 1` deviations of each worker's
    episode (`ld_history`; None for a window of 1), zeros at an episode's start. The
    deviation is scaled by `ld_scale` before the window and K.
    """
    estimate, degree = LD_ESTIMATES[dynamics.config.ld]
    scale, penalty = dynamics.config.ld_scale, dynamics.config.penalty
    is_terminal, model_action, env_reward = facts.is_terminal, facts.model_action, facts.env_reward
    true_step = facts.true_step

    def step(key: Array, world: Array | None, obs: Array, action: Array, alive: Array):
        encoded = model_action(action)
        k_model = jax.random.fold_in(key, MODEL_STREAM)  # the stop rule draws from `key`
        predicted, uncertainty = estimate(dynamics, model, obs, encoded, k_model)
        statistic, world = windowed(scale * uncertainty, world)
        ld, p_stop = degree(statistic, gain)
        next_obs, reward = dynamics.denormalize(model.stats, *predicted)
        if env_reward is not None:
            reward = env_reward(obs, action, next_obs)
        view = StepView(obs, action, next_obs, p_stop, statistic, alive)
        ends = stop(key, view)
        terminated = is_terminal(next_obs)
        outside = ~dynamics.within_bounds(model, next_obs)
        if true_step is not None:
            k_true = jax.random.fold_in(key, TRUE_STREAM)
            true_obs, true_rewards, terminated = true_step(k_true, obs, action)
            if facts.true_reward:
                reward = true_rewards
            if facts.true_state:
                next_obs, outside = true_obs, jnp.zeros_like(outside)
        if not (isinstance(penalty, float) and penalty == 0.0):  # a sweep's value is traced
            reward = reward - penalty * uncertainty
        extras = {"ld": ld}
        if model.bounds is not None:
            extras["outside"] = outside & ~terminated
        return next_obs, world, reward, terminated, ends | outside, extras

    return step


@struct.dataclass
class StepView:
    """What a stopping rule sees of one imagined step of W workers, each field `[W, ...]`."""

    obs: Array
    action: Array
    """The action the env would execute (continuous: clipped)."""
    next_obs: Array
    """The model's predicted next observation, in the env's units."""
    p_stop: Array
    """The learning degree's stop probability 1 - LD (eq. 5)."""
    statistic: Array
    """The estimator's deviation after scale and window: eq. 3's sigma2 (`ld` "m0"), or
    the ensemble's disagreement relative to its fit error (`ld` "ensemble")."""
    alive: Array
    """Which workers' imagined episodes are still running (bool)."""


MODEL_STREAM = 0x5EED
"""`jax.random.fold_in` data of a probabilistic model's draws (which member, which sample)
in each imagined step: a branch off the step's key, which the stopping rule draws from."""

TRUE_STREAM = 0x7E11
"""`jax.random.fold_in` data of the real env's step in a world that steps it
(`ModelConfig.world` "true")."""

StopRule = Callable[[Array, StepView], Array]
"""`(key, step) -> stop [W]` bool: end the episode after this step (a truncation)."""


def stop_rule(
    config: StopConfig,
    name: str,
    true_next: Callable | None = None,
    threshold: Array | None = None,
) -> StopRule:
    """The rule `name` (one of `STOP_RULES`) with `config`'s parameters. `true_next(key,
    obs, action) -> next_obs`: the real env stepped from imagined observations, needed
    by "oracle" only; `threshold`: "macura"'s (`macura_threshold`). "horizon" and "mbpo"
    stop nothing here: their cut is the episode's step limit (`imagined_steps_limit`,
    `scheduled_horizon`)."""
    if name == "ld":
        return lambda key, step: stop_draw(key, step.p_stop)
    if name in ("none", "horizon", "mbpo"):
        return lambda key, step: jnp.zeros(step.alive.shape, bool)
    if name == "macura":
        if threshold is None:
            raise ValueError("the macura stop needs its threshold (macura_threshold)")
        return lambda key, step: step.statistic > threshold
    if name == "m2ac":
        keep = config.m2ac_keep
        return lambda key, step: step.alive & ~m2ac_kept(step.statistic, step.alive, keep)
    if name == "oracle":
        if true_next is None:
            raise ValueError("the oracle stop needs the real env's step (true_next)")
        threshold = config.oracle_error

        def oracle(key: Array, step: StepView) -> Array:
            truth = true_next(key, step.obs, step.action)
            return oracle_error(step.next_obs, truth) > threshold

        return oracle
    raise ValueError(f"unknown stop rule {name!r}; valid: {', '.join(STOP_RULES)}")


def m2ac_kept(score: Array, alive: Array, keep: Array | float) -> Array:
    """The running rollouts (`alive [W]`) an M2AC-style mask keeps: the keep x n of the n
    running ones with the lowest `score [W]` (ties: the lower worker index), to the nearest
    whole count with halves down, so a last rollout is kept only where keep > 1/2: none
    imagines on however unsure the ensemble. `[W] bool`."""
    running = alive.sum()
    count = jnp.ceil(keep * running - 0.5)
    ranks = jnp.argsort(jnp.argsort(jnp.where(alive, score, jnp.inf), stable=True), stable=True)
    return alive & (ranks < count)


def macura_threshold(first: Array, quantile: Array | float, scale: Array | float) -> Array:
    """MACURA's adaptive cut: `scale` times the `quantile` quantile of the disagreement `[N]`
    of the first imagined step from N start states (linear interpolation between order
    statistics). Its reading here: recomputed each iteration from that iteration's starts."""
    return scale * jnp.quantile(first, quantile)


def first_step_statistic(
    dynamics: Dynamics, model: ModelState, obs: Array, action: Array, key: Array
) -> Array:
    """The estimator's deviation `[N]` of one step from `obs [N, d]` with the encoded
    `action`, scaled by `ld_scale` (a window's first step is the step itself)."""
    _, statistic = LD_ESTIMATES[dynamics.config.ld][0](dynamics, model, obs, action, key)
    return dynamics.config.ld_scale * statistic


def scheduled_horizon(config: StopConfig, env_steps: Array) -> Array:
    """MBPO's rollout length after `env_steps` real steps: `horizon_min` until
    `horizon_from`, `horizon_max` from `horizon_to`, linear between, rounded down; int32."""
    span = max(config.horizon_to - config.horizon_from, 1)
    progress = jnp.clip((env_steps - config.horizon_from) / span, 0.0, 1.0)
    grown = config.horizon_min + progress * (config.horizon_max - config.horizon_min)
    return jnp.floor(grown).astype(jnp.int32)


def oracle_error(predicted: Array, truth: Array) -> Array:
    """The one-step error the oracle reads: ||predicted - truth|| over the observation,
    `[..., D] x2 -> [...]` (the calibration's `one_step_error`)."""
    return jnp.linalg.norm(predicted - truth, axis=-1)


def imagined_steps_limit(config: StopConfig, name: str, max_steps: int) -> int:
    """The step limit of an imagined episode: the env's, or under "horizon" at most
    `config.horizon`."""
    return min(max_steps, config.horizon) if name == "horizon" else max_steps


def ld_history(dynamics: Dynamics, workers: int) -> Array | None:
    """The model world's state at an episode's start: `ld_window - 1` zeros per worker (no
    steps taken yet), or None for a window of 1."""
    window = dynamics.config.ld_window
    return None if window == 1 else jnp.zeros((workers, window - 1), jnp.float32)


def _m0_estimate(dynamics: Dynamics, model: ModelState, obs: Array, action: Array, key: Array):
    """M1's normalised prediction, and eq. 3's sigma2 of M1 vs M0 (a probabilistic
    ensemble: `_gaussian_estimate`, of the drawn member against its own M0)."""
    if dynamics.probabilistic:
        return _gaussian_estimate(dynamics, model, obs, action, key, "m0")
    del key  # deterministic
    m1 = dynamics.predict_normalized(model.params, model.stats, obs, action)
    m0 = dynamics.predict_normalized(model.frozen, model.stats, obs, action)
    return m1, deviation(_joined(*m1), _joined(*m0), dynamics.config.ld_reduce)


def _m0_degree(sigma2: Array, gain: Array):
    """LD and P(stop) of eq. 4-6."""
    return learning_degree(sigma2, gain), stop_probability(sigma2, gain)


def _ensemble_estimate(
    dynamics: Dynamics, model: ModelState, obs: Array, action: Array, key: Array
):
    """The members' mean normalised prediction, and their disagreement relative to their
    fit error (a probabilistic ensemble: `_gaussian_estimate`)."""
    if dynamics.probabilistic:
        return _gaussian_estimate(dynamics, model, obs, action, key, "ensemble")
    members = _joined(*dynamics.predict_members(model.params, model.stats, obs, action))
    mean = ensemble_mean(members)
    d = disagreement(members, dynamics.config.ld_reduce)
    predicted = (mean[..., :-1], mean[..., -1])
    return predicted, relative_disagreement(d, model.error_scale)


def _ensemble_degree(d_rel: Array, gain: Array):
    return ensemble_learning_degree(d_rel, gain), ensemble_stop_probability(d_rel, gain)


def _gaussian_estimate(
    dynamics: Dynamics, model: ModelState, obs: Array, action: Array, key: Array, reading: str
):
    """A probabilistic ensemble's step: a sample of one elite drawn per row (or, under
    `imagined_step` "mean", the elites' mean prediction), and either the
    elites' disagreement on their means ("ensemble") or the drawn member's mean predicted
    variance, halved as eq. 3 halves ("variance"), relative to the held-out error; or
    ("m0") eq. 3's sigma2 of the drawn member's mean against its frozen initial copy's, as
    the paper reads M1 against M0 (not relative: eq. 4-6 take it as it is)."""
    mean, log_var = jax.vmap(dynamics.predict_gaussian, (0, None, None, None))(
        model.params, model.stats, obs, action
    )  # [E, N, D + 1]
    k_member, k_noise = jax.random.split(key)
    pick = jax.random.randint(k_member, obs.shape[:-1], 0, model.elites.shape[0])
    member = model.elites[pick]  # [N]
    chosen = lambda x: jnp.take_along_axis(x, member[None, :, None], axis=0)[0]
    centre, chosen_log_var = chosen(mean), chosen(log_var)
    if dynamics.config.imagined_step == "mean":
        sample = ensemble_mean(mean[model.elites])
    else:
        noise = jax.random.normal(k_noise, centre.shape)
        sample = centre + jnp.exp(0.5 * chosen_log_var) * noise
    reduce = dynamics.config.ld_reduce
    if reading == "m0":
        initial, _ = jax.vmap(dynamics.predict_gaussian, (0, None, None, None))(
            model.frozen, model.stats, obs, action
        )
        return (sample[..., :-1], sample[..., -1]), deviation(centre, chosen(initial), reduce)
    if reading == "variance":
        d = 0.5 * REDUCE[reduce](jnp.exp(chosen_log_var), axis=-1)
    else:
        d = disagreement(mean[model.elites], reduce)
    return (sample[..., :-1], sample[..., -1]), relative_disagreement(d, model.error_scale)


def _variance_estimate(
    dynamics: Dynamics, model: ModelState, obs: Array, action: Array, key: Array
):
    return _gaussian_estimate(dynamics, model, obs, action, key, "variance")


LD_ESTIMATES = {
    "m0": (_m0_estimate, _m0_degree),
    "ensemble": (_ensemble_estimate, _ensemble_degree),
    "variance": (_variance_estimate, _ensemble_degree),
}
"""`ModelConfig.ld` -> `(estimate, degree)`: `estimate(dynamics, model, obs, action, key) ->
(prediction, deviation)` (`key`: a probabilistic model's draws) and `degree(deviation,
gain) -> (LD, P(stop))`, the deviation scaled and windowed between them (`model_world`):
the learning-degree estimators, as `LEARNERS` holds the learners. A new estimator is a pair
here and its name in `ldn_jax.config.LD_ESTIMATORS`."""
assert tuple(LD_ESTIMATES) == LD_ESTIMATORS, "estimators and their config names disagree"


def _joined(next_obs: Array, reward: Array) -> Array:
    """The model's output as eq. 2 and 3 see it: `[..., D], [...] -> [..., D + 1]`."""
    return jnp.concatenate([next_obs, reward[..., None]], axis=-1)
