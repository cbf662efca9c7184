"""What every learner consumes: a time-major segment of (possibly masked) transitions."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

Array = jax.Array


@struct.dataclass
class Segment:
    """Transitions of W workers over n steps, time-major: every field `[n, W, ...]`."""

    obs: Array
    action: Array
    reward: Array
    next_obs: Array
    terminated: Array
    """The next state is terminal: no future value, no bootstrap."""
    done: Array
    """The episode ended here (terminated, truncated, or stopped by the LD draw)."""
    weight: Array
    """1.0 for a live transition, 0.0 for a masked one (its worker's episode had ended)."""


@struct.dataclass
class LearnerState:
    params: dict
    opt_state: tuple


def worker_mean(x: Array, weight: Array) -> Array:
    """Mean over each worker's live steps, then over workers with any: `[n, W] -> []`.

    Its gradient is the average of the workers' gradients, as in synchronous A3C.
    Masked entries are selected away (not multiplied), so a NaN there cannot leak.
    """
    live = weight > 0
    total = jnp.where(live, x * weight, 0.0).sum(0)
    count = weight.sum(0)
    per_worker = total / jnp.maximum(count, 1.0)
    active = count > 0
    return jnp.where(active, per_worker, 0.0).sum() / jnp.maximum(active.sum(), 1)


def keep_if_any(new, old, weight: Array):
    """`new` where the segment has any live transition, else `old`.

    An empty segment must not touch the optimiser: a zero gradient would still decay
    RMSProp's and Adam's moment estimates.
    """
    any_live = weight.sum() > 0
    return jax.tree.map(lambda n, o: jnp.where(any_live, n, o), new, old)


def masked_obs(obs: Array, weight: Array) -> Array:
    """Zero the observations of masked steps so their (unused) forward passes stay finite."""
    return jnp.where(weight[..., None] > 0, obs, 0.0)
