"""Does the learning degree know when the model is wrong? Shadow rollouts (analysis only).

Imagined episodes are played in M1 as training plays them (the sampled policy, from a fresh
initial state, until predicted termination or the step limit), and the real env is stepped
alongside with the same actions (the "shadow"). Per imagined step this records:
- `one_step_error`: ||M1(s_t, a_t) - env(s_t, a_t)|| on the next state, from the imagined s_t;
- `compounding_error`: ||s^_{t+1} - s_{t+1}||, the imagined trajectory against the real one
  played from the same initial state with the same actions;
- the learning degree of M1 vs M0 (eq. 3-6) and whether the LD draw would have stopped here;
- optionally the disagreement of an ensemble of E extra models fitted on the same real buffer,
  mapped to a learning degree with the same K as `--ld ensemble` trains with: relative to the
  members' fit error, LD = 2 sigmoid(-K d / error) (`ensemble_learning_degree`).

Nothing here changes training: it reads a `TrainState` and returns arrays.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct
from scipy import stats

from ldn_jax.config import Config
from ldn_jax.host.run_dir import RunDir
from ldn_jax.learning_degree import (
    deviation,
    disagreement,
    ensemble_learning_degree,
    learning_degree,
    relative_disagreement,
    stop_draw,
    stop_probability,
)
from ldn_jax.trainer import Trainer, TrainState

Array = jax.Array


@struct.dataclass
class ShadowSteps:
    """Per imagined step, time-major: every field `[T, N]` (T = the env's step limit,
    N episodes). Steps after an episode's end are kept (masks below say which count)."""

    ld: Array
    """Learning degree of M1 vs M0 (eq. 3-6, the run's K and reading of eq. 3)."""
    sigma2: Array
    """Eq. 3's deviation of M1 from M0 (LD before the sigmoid, unsaturated), reduced over
    the outputs and scaled as the run reads it (`model.ld_reduce`, `model.ld_scale`)."""
    sigma2_reward: Array
    """The reward's term of sigma2 (sigma2 minus the next state's)."""
    one_step_error: Array
    compounding_error: Array
    step_size: Array
    """||env(s_t, a_t) - s_t||: how far the real env moves from the imagined state in one
    step (the scale `one_step_error` is read against)."""
    reward: Array
    """The imagined step's reward as the learner sees it (M1's prediction)."""
    true_reward: Array
    """The real env's reward for the same step from the imagined state."""
    disagreement: Array
    """Ensemble disagreement: 1/2 the variance over members, reduced over output dims and
    scaled as the run reads eq. 3; zero without an ensemble."""
    ensemble_ld: Array
    """The ensemble's learning degree, 2 sigmoid(-K d / error_scale) (one without one)."""
    live: Array
    """The imagined episode is running: before predicted termination (the a2c-model rule)."""
    ld_live: Array
    """... and the LD draw has not stopped it yet: the steps MBRL-LDN trains on."""
    ensemble_live: Array
    """... and a draw with the ensemble's learning degree has not stopped it yet."""
    real_live: Array
    """The shadow real episode has not terminated before this step."""


def _predict(
    trainer: Trainer, params: dict, stats, obs: Array, onehot: Array, normalized: bool = False
) -> Array:
    """`[N, obs], [N, A] -> [N, obs + 1]`: the model's [s', r] under its normaliser `stats`
    (`ModelState.stats`), as training imagines them; `normalized`: in the model's own output
    units, where eq. 3 and the disagreement are read (the raw ones without `model.normalize`)."""
    dynamics = trainer.dynamics
    next_obs, reward = dynamics.predict_normalized(params, stats, obs, onehot)
    if not normalized:
        next_obs, reward = dynamics.denormalize(stats, next_obs, reward)
    return jnp.concatenate([next_obs, reward[..., None]], axis=-1)


def _as_imagined(trainer: Trainer, stats, own: Array, obs: Array, action: Array, env_reward):
    """M1's prediction in its own units (`_predict(..., normalized=True)`) as the run imagines
    the step: the next observation and reward in the env's units, the reward the env's own
    where the run used it (`env_reward`, None otherwise)."""
    next_obs, reward = trainer.dynamics.denormalize(stats, own[..., :-1], own[..., -1])
    if env_reward is not None:
        reward = env_reward(obs, action, next_obs)
    return next_obs, reward


def shadow_rollouts(
    trainer: Trainer,
    state: TrainState,
    key: Array,
    episodes: int,
    k: Array | float,
    ensemble: dict | None = None,
    error_scale: Array | float = 1.0,
) -> ShadowSteps:
    """Play `episodes` imagined episodes in one run's M1 with the real env alongside.

    `state` is one seed's (unbatched) state of a model-based run; `ensemble` is a stack of
    model parameters `[E, ...]` (see `fit_ensemble`) or None, and `error_scale` the members'
    fit MSE that their disagreement is measured against (as `ModelState.error_scale` in a run
    trained with `--ld ensemble`).
    """
    env, params = trainer.env, trainer.env_params
    if not hasattr(env, "from_observation"):  # `ldn_jax.envs.base`: the optional method
        raise ValueError(f"shadow rollouts need an env whose observation is its state, not {env}")
    if trainer.dynamics is None:
        raise ValueError("shadow rollouts need a model-based run (a2c-model, ldn, ...)")
    _check_single_model(trainer)
    reading = trainer.config.model
    if reading.ld_window != 1:
        raise ValueError(
            "shadow rollouts read each step's own deviation; this run's LD sums a window of "
            f"{reading.ld_window} steps (model.ld_window)"
        )
    scale, reduce = reading.ld_scale, reading.ld_reduce
    outputs = 1 if reduce == "sum" else trainer.obs_size + 1  # what the reward's term is over
    from_obs = jax.vmap(lambda o: env.from_observation(o, params))
    step = jax.vmap(env.step, (0, 0, 0, None))
    stats = state.model.stats
    env_reward = trainer.parts.real.exact_reward(trainer.config.model.env_reward)
    k_reset, k_play = jax.random.split(key)
    obs, real = jax.vmap(env.reset, (0, None))(jax.random.split(k_reset, episodes), params)
    ones = jnp.ones((episodes,), bool)

    def body(carry, key):
        imagined, real, live, ld_live, ensemble_live, real_live = carry
        k_act, k_stop, k_ensemble, k_env = jax.random.split(key, 4)
        action = trainer.learner.act(state.learner.params, k_act, imagined)
        onehot = trainer.model_action(action)
        own = lambda p: _predict(trainer, p, stats, imagined, onehot, normalized=True)
        predicted, frozen = own(state.model.params), own(state.model.frozen)
        sigma2 = scale * deviation(predicted, frozen, reduce)
        sigma2_reward = scale * 0.5 * jnp.square(predicted[..., -1] - frozen[..., -1]) / outputs
        stop = stop_draw(k_stop, stop_probability(sigma2, k))
        env_keys = jax.random.split(k_env, episodes)
        true_next, _, true_reward = step(env_keys, from_obs(imagined), action, params)[:3]
        real_next, real, _, real_terminated, _, _ = step(env_keys, real, action, params)
        next_obs, reward = _as_imagined(trainer, stats, predicted, imagined, action, env_reward)
        if ensemble is None:
            spread = jnp.zeros_like(sigma2)
        else:
            members = jax.vmap(own)(ensemble)
            spread = scale * disagreement(members, reduce)
        p_continue = ensemble_learning_degree(relative_disagreement(spread, error_scale), k)
        ensemble_stop = jax.random.uniform(k_ensemble, p_continue.shape) >= p_continue
        out = ShadowSteps(
            ld=learning_degree(sigma2, k),
            sigma2=sigma2,
            sigma2_reward=sigma2_reward,
            one_step_error=jnp.linalg.norm(next_obs - true_next, axis=-1),
            compounding_error=jnp.linalg.norm(next_obs - real_next, axis=-1),
            step_size=jnp.linalg.norm(true_next - imagined, axis=-1),
            reward=reward,
            true_reward=true_reward,
            disagreement=spread,
            ensemble_ld=p_continue,
            live=live,
            ld_live=ld_live,
            ensemble_live=ensemble_live,
            real_live=real_live,
        )
        live = live & ~env.is_terminal(next_obs, params)
        carry = (
            next_obs,
            real,
            live,
            ld_live & live & ~stop,
            ensemble_live & live & ~ensemble_stop,
            real_live & ~real_terminated,
        )
        return carry, out

    init = (obs, real, ones, ones, ones, ones)
    keys = jax.random.split(k_play, trainer.max_steps)
    return jax.lax.scan(body, init, keys)[1]


def policy_rollouts(
    trainer: Trainer, state: TrainState, key: Array, episodes: int
) -> tuple[Array, Array, Array]:
    """`episodes` episodes of one seed's sampled policy from fresh initial states, played in
    the real env and, from the same initial states, in its M1 (the a2c-model rule: until
    predicted termination or the step limit).

    Returns the critic's value of the initial states `[N]` (in standardised units under
    `agent.normalize_reward`), and each episode's discounted return (the run's gamma) in the
    real env and in M1 `[N]`: what the critic's targets are built from on real episodes,
    and on imagined ones."""
    env, params, learner = trainer.env, trainer.env_params, trainer.learner
    gamma = trainer.config.agent.gamma
    env_reward = trainer.parts.real.exact_reward(trainer.config.model.env_reward)
    step = jax.vmap(env.step, (0, 0, 0, None))
    k_real, k_imagined, k_reset = jax.random.split(key, 3)
    obs, real = jax.vmap(env.reset, (0, None))(jax.random.split(k_reset, episodes), params)
    value = learner.value(state.learner.params, obs)

    def real_body(carry, key):
        obs, real, live, discount, total = carry
        k_act, k_env = jax.random.split(key)
        action = learner.act(state.learner.params, k_act, obs)
        obs, real, reward, terminated, _, _ = step(
            jax.random.split(k_env, episodes), real, action, params
        )
        total = total + jnp.where(live, discount * reward, 0.0)
        return (obs, real, live & ~terminated, discount * gamma, total), None

    def imagined_body(carry, key):
        obs, live, discount, total = carry
        action = learner.act(state.learner.params, key, obs)
        stats, onehot = state.model.stats, trainer.model_action(action)
        own = _predict(trainer, state.model.params, stats, obs, onehot, normalized=True)
        next_obs, reward = _as_imagined(trainer, stats, own, obs, action, env_reward)
        total = total + jnp.where(live, discount * reward, 0.0)
        live = live & ~env.is_terminal(next_obs, params)
        return (next_obs, live, discount * gamma, total), None

    ones, zeros = jnp.ones((episodes,), bool), jnp.zeros((episodes,))
    keys = lambda k: jax.random.split(k, trainer.max_steps)
    real_return = jax.lax.scan(real_body, (obs, real, ones, 1.0, zeros), keys(k_real))[0][-1]
    imagined_return = jax.lax.scan(imagined_body, (obs, ones, 1.0, zeros), keys(k_imagined))
    return value, real_return, imagined_return[0][-1]


def fit_ensemble(
    trainer: Trainer, state: TrainState, key: Array, members: int, rounds: int
) -> tuple[dict, Array]:
    """E models of M1's architecture from fresh initialisations, each fitted like M1 for
    `rounds` x `fit.updates` minibatch steps on the run's real buffer (its own minibatches).

    Returns their parameters stacked `[E, ...]` and each member's last mean loss `[E]`.
    M1 saw the buffer grow over training; the members see only its final content.
    """
    _check_single_model(trainer)
    dynamics = trainer.dynamics

    def member(key: Array):
        k_init, k_fit = jax.random.split(key)
        model = dynamics.init(k_init)
        fit = lambda model, key: dynamics.fit(model, state.buffer, key)
        model, losses = jax.lax.scan(fit, model, jax.random.split(k_fit, rounds))
        return model.params, losses[-1] if rounds else jnp.zeros(())

    return jax.vmap(member)(jax.random.split(key, members))


def _check_single_model(trainer: Trainer) -> None:
    if trainer.dynamics is not None and trainer.dynamics.ensemble:
        raise ValueError(
            "calibration compares M1 with M0; this run trained an ensemble (ld = ensemble)"
        )


def load_run(run_dir: str | Path) -> tuple[Config, Trainer, TrainState]:
    """A finished run's config, trainer and batched final state `[K, S]` (as `load_policy`)."""
    run = RunDir(run_dir)
    config = run.read_config()
    trainer = Trainer(config)
    states = run.restore_final(jax.eval_shape(trainer.init_batch))
    return config, trainer, states


# -- host-side summaries (numpy) -----------------------------------------------------------

HORIZON_EDGES = (1, 2, 3, 5, 10, 20, 50, 100, 200, 500, 1000)
"""Bins of the imagined-horizon histograms: [1, 2), [2, 3), ..., [500, 1000), [1000, inf)."""


def auc(score: np.ndarray, positive: np.ndarray) -> float | None:
    """ROC AUC of `score` for the labels `positive` (Mann-Whitney, ties counted half)."""
    n_pos, n_neg = int(positive.sum()), int((~positive).sum())
    if n_pos == 0 or n_neg == 0:
        return None
    ranks = stats.rankdata(score)
    return float((ranks[positive].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def _finite(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def association(score: np.ndarray, error: np.ndarray) -> dict:
    """Pearson and Spearman correlation of `score` with `error`, and the ROC AUC of `score`
    for "error above its median". 1 - AUC is the AUC of the reversed score."""
    if score.size < 3 or np.ptp(score) == 0 or np.ptp(error) == 0:
        return {"pearson": None, "spearman": None, "auc_error_above_median": None}
    return {
        "pearson": _finite(np.corrcoef(score, error)[0, 1]),
        "spearman": _finite(stats.spearmanr(score, error).statistic),
        "auc_error_above_median": auc(score, error > np.median(error)),
    }


def horizons(lengths: np.ndarray) -> dict:
    """Distribution of imagined episode lengths `[N]`."""
    counts, _ = np.histogram(lengths, bins=[*HORIZON_EDGES, np.inf])
    return {
        "episodes": int(lengths.size),
        "mean": float(lengths.mean()),
        "median": float(np.median(lengths)),
        "p90": float(np.percentile(lengths, 90)),
        "max": int(lengths.max()),
        "bin_edges": list(HORIZON_EDGES),
        "counts": counts.tolist(),
    }


SCORES = ("ld", "sigma2", "disagreement")


def calibration_summary(steps: ShadowSteps) -> dict:
    """Correlations and AUCs of each score with each error, and the horizon distributions.

    `steps` holds numpy arrays `[T, N]` (or `[T, N']` pooled). Two populations of steps:
    `imagined`, every step before predicted termination (the a2c-model rule), and `ld_rule`,
    the steps the LD draw lets MBRL-LDN train on. The compounding error counts only while the
    shadow real episode is running too. Non-finite errors (a diverged model) are left out and
    counted.
    """
    summary = {}
    for population, mask in (("imagined", steps.live), ("ld_rule", steps.ld_live)):
        entry = {"steps": int(mask.sum())}
        for error_name, valid in (
            ("one_step_error", mask),
            ("compounding_error", mask & steps.real_live),
        ):
            error = getattr(steps, error_name)
            keep = valid & np.isfinite(error)
            per_score = {
                score: association(getattr(steps, score)[keep], error[keep]) for score in SCORES
            }
            per_score["steps"] = int(keep.sum())
            per_score["non_finite"] = int((valid & ~np.isfinite(error)).sum())
            per_score["median"] = _finite(np.median(error[keep])) if keep.any() else None
            entry[error_name] = per_score
        ld, sigma2 = steps.ld[mask], steps.sigma2[mask].sum()
        entry["ld"] = {
            "mean": _finite(ld.mean()) if ld.size else None,
            "quantiles_10_50_90": np.percentile(ld, [10, 50, 90]).tolist() if ld.size else None,
            "sigma2_mean": _finite(steps.sigma2[mask].mean()) if ld.size else None,
            "sigma2_reward_share": _finite(steps.sigma2_reward[mask].sum() / sigma2)
            if sigma2 > 0
            else None,
        }
        ens = steps.ensemble_ld[mask]
        entry["ensemble_ld"] = {
            "mean": _finite(ens.mean()) if ens.size else None,
            "quantiles_10_50_90": np.percentile(ens, [10, 50, 90]).tolist() if ens.size else None,
        }
        summary[population] = entry
    summary["horizons"] = {
        "predicted_termination": horizons(steps.live.sum(0)),
        "ld_rule": horizons(steps.ld_live.sum(0)),
        "ensemble_rule": horizons(steps.ensemble_live.sum(0)),
    }
    return summary


def binned_error(score: np.ndarray, error: np.ndarray, bins: int = 10) -> dict:
    """Mean error per quantile bin of `score` (a calibration curve that works however
    concentrated the score is)."""
    if score.size == 0:
        return {"score_mean": [], "error_mean": [], "count": []}
    edges = np.unique(np.quantile(score, np.linspace(0, 1, bins + 1)))
    index = np.clip(np.searchsorted(edges, score, side="right") - 1, 0, max(len(edges) - 2, 0))
    out = {"score_mean": [], "error_mean": [], "count": []}
    for b in range(max(len(edges) - 1, 1)):
        hit = index == b
        if hit.any():
            out["score_mean"].append(float(score[hit].mean()))
            out["error_mean"].append(float(error[hit].mean()))
            out["count"].append(int(hit.sum()))
    return out
