"""The model's stage: the real transitions into the buffer R, then M1's fit on it (and the
termination classifier's, where it is learned)."""

from __future__ import annotations

import jax

from ldn_jax.buffer import Transitions, buffer_add
from ldn_jax.dynamics import TERMINATION_STREAM, EarlyStop
from ldn_jax.rollout import Episodes
from ldn_jax.stages.parts import Parts, TrainState

Array = jax.Array


def fit(parts: Parts, state: TrainState, real: Episodes, key: Array) -> tuple[TrainState, dict]:
    """The iteration's real steps (`[T, W, ...]`, those of weight > 0) into R, and
    `fit.updates` minibatch steps of M1 on R (`fit.early_stop`: MBPO's fit toward
    convergence, at most `fit.updates` steps where that is not 0); the fit's metrics:
    `model_loss` (and `model_epochs` under early_stop)."""
    steps = real.steps
    flat = lambda x: x.reshape((-1, *x.shape[2:]))
    batch = Transitions(
        obs=flat(steps.obs),
        action=flat(parts.model_action(steps.action)),
        next_obs=flat(steps.next_obs),
        reward=flat(steps.reward),
    )
    learned = parts.config.imagine.termination == "learned"
    if learned:
        batch = batch.replace(terminated=flat(steps.terminated).astype(batch.reward.dtype))
    buffer = buffer_add(state.buffer, batch, flat(steps.weight) > 0)
    value = None
    if parts.config.fit.value_loss:
        value = lambda obs: parts.learner.value(state.learner.params, obs)
    if parts.config.fit.early_stop:
        stop = EarlyStop(max_steps=parts.config.fit.updates)
        model, loss, epochs = parts.dynamics.fit_until_stalled(state.model, buffer, key, stop)
        fitted = {"model_loss": loss, "model_epochs": epochs.astype(loss.dtype)}
    else:
        model, loss = parts.dynamics.fit(state.model, buffer, key, value)
        fitted = {"model_loss": loss}
    if learned:  # a key of its own: M1's fit keeps its draws
        k_done = jax.random.fold_in(key, TERMINATION_STREAM)
        model, fitted["termination_loss"] = parts.dynamics.fit_termination(model, buffer, k_done)
    return state.replace(model=model, buffer=buffer), fitted
