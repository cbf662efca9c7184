"""The failure guard: a run whose iteration made a checked quantity non-finite keeps its last
finite state from then on (frozen), and `TrainState.failure` says what diverged; the other
vmapped runs go on. A run past its budget is frozen the same way."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ldn_jax.stages.parts import TrainState

Array = jax.Array

FAILURES = (
    "actor-critic parameters",
    "model parameters",
    "real-stage losses",
    "model loss",
    "imagined-stage losses or returns",
    "episode returns",
)
"""What the guard checks, in the order of the bits of `TrainState.failure`."""


def failure_names(failure: int) -> list[str]:
    """The names of the quantities whose bits are set in a `TrainState.failure` value."""
    return [name for bit, name in enumerate(FAILURES) if failure >> bit & 1]


def guarded(
    old: TrainState, new: TrainState, metrics: dict, spent: Array
) -> tuple[TrainState, dict]:
    """`new`, or `old` where the run has failed (now or before) or was `spent` before this
    iteration; the metrics' moving returns follow the state kept."""
    failure = _failure(new, metrics)
    first = (old.failure == 0) & (failure != 0) & ~spent
    frozen = (old.failure != 0) | first | spent
    kept = jax.tree.map(lambda n, o: jnp.where(frozen, o, n), new, old)
    state = kept.replace(
        failure=jnp.where(first, failure, old.failure),
        failed_iteration=jnp.where(first, new.iteration, old.failed_iteration),
    )
    metrics["moving_after"] = jnp.where(frozen, state.moving_return, metrics["moving_after"])
    return state, metrics


def _failure(state: TrainState, metrics: dict) -> Array:
    """The `FAILURES` bits of the quantities of one iteration that are not all finite."""
    stage = lambda prefix: {n: v for n, v in metrics.items() if n.startswith(prefix)}
    checks = [
        state.learner.params,
        state.model.params if state.model is not None else (),
        stage("real_"),
        metrics.get("model_loss", ()),
        stage("imagined_"),
        metrics["returns"],
    ]
    bad = jnp.stack([~_all_finite(tree) for tree in checks])
    return (bad.astype(jnp.int32) << jnp.arange(len(checks))).sum()


def _all_finite(tree) -> Array:
    leaves = [jnp.isfinite(x).all() for x in jax.tree.leaves(tree)]
    return jnp.stack(leaves).all() if leaves else jnp.ones((), bool)
