"""The learning degree (eq. 3-6) and the stop draw that ends imagined episodes.

LD measures how far the trained model M1 has moved from its frozen initial copy M0 on an
input: near 0 where M1 has learned nothing (imagination stops at once), towards 1 where it has
learned much (imagination goes on).

The alternative estimator (`ModelConfig.ld = "ensemble"`) reads the disagreement of E
independently initialised models instead, relative to their own fit error: LD is near 1 where
they agree and falls as they disagree.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

Array = jax.Array


REDUCE = {"mean": jnp.mean, "sum": jnp.sum}
"""`ModelConfig.ld_reduce` -> the reduction over output dims."""


def deviation(pred_m1: Array, pred_m0: Array, reduce: str = "mean") -> Array:
    """Eq. 3: sigma2 = 1/2 (M1 - M0)^2, reduced by the mean (or the sum) over output dims.

    `[..., D], [..., D] -> [...]`.
    """
    return 0.5 * REDUCE[reduce](jnp.square(pred_m1 - pred_m0), axis=-1)


def windowed(value: Array, history: Array | None) -> tuple[Array, Array | None]:
    """The sum of `value` and the last B - 1 values of its episode (`history [..., B - 1]`,
    zeros for steps not taken yet: at the episode start the window holds only the steps so
    far), and the history with `value` pushed in. `history=None`: a window of 1."""
    if history is None:
        return value, None
    total = value + history.sum(axis=-1)
    return total, jnp.concatenate([history[..., 1:], value[..., None]], axis=-1)


def learning_degree(sigma2: Array, gain: Array | float = 1.0) -> Array:
    """Eq. 4 and 6: LD = 2 sigmoid(K sigma2) - 1, in [0, 1) for sigma2 >= 0.

    Computed as the identical tanh(K sigma2 / 2), which keeps its precision near 0 where
    2 sigmoid(x) - 1 cancels. In float32 LD rounds to 1 above K sigma2 ~ 17; draws use
    `stop_probability`, which stays exact there.
    """
    return jnp.tanh(0.5 * gain * sigma2)


def stop_probability(sigma2: Array, gain: Array | float = 1.0) -> Array:
    """Eq. 5: P(stop) = 1 - LD = 2 sigmoid(-K sigma2), computed without cancellation."""
    return 2.0 * jax.nn.sigmoid(-gain * sigma2)


def stop_draw(key: Array, p_stop: Array) -> Array:
    """Stop where u < P(stop), u ~ U[0, 1): with P(stop) = 1 - LD this is eq. 5."""
    return jax.random.uniform(key, p_stop.shape) < p_stop


# -- the ensemble estimator ------------------------------------------------------------------

ERROR_FLOOR = 1e-10
"""Floor of the error scale that disagreement is divided by: only guards against a zero scale
(a fit of zero updates); real fit losses are far above it (linear members on CartPole: ~1e-6)."""


def ensemble_mean(members: Array) -> Array:
    """The members' mean prediction: `[E, ..., D] -> [..., D]`.

    Taken as member 0 plus the mean deviation from it, which is exactly member 0 when all
    members agree (a plain mean of E equal float32 values need not round back to them).
    """
    return members[0] + jnp.mean(members - members[0], axis=0)


def disagreement(members: Array, reduce: str = "mean") -> Array:
    """Eq. 3's form on an ensemble: d = 1/2 the variance over members, reduced over output
    dims by the mean (or the sum).

    `[E, ..., D] -> [...]`; exactly 0 when all members agree.
    """
    centred = members - ensemble_mean(members)
    return 0.5 * REDUCE[reduce](jnp.mean(jnp.square(centred), axis=0), axis=-1)


def relative_disagreement(d: Array, error_scale: Array | float) -> Array:
    """d / max(error_scale, `ERROR_FLOOR`): disagreement in units of the members' fit MSE.

    Well-fitted members disagree by tiny amounts in absolute terms (linear ones on CartPole:
    ~1e-6), which would make K meaningless; relative to the error the members are known to
    make, d_rel ~ 1 means "they disagree as much as they err".
    """
    return d / jnp.maximum(error_scale, ERROR_FLOOR)


def ensemble_learning_degree(d: Array, gain: Array | float = 1.0) -> Array:
    """Eq. 4/6's mapping applied to ensemble disagreement, flipped: 2 sigmoid(-K d), in (0, 1].

    M1's deviation from M0 grows with what it has learned; disagreement grows with what the
    models do not know. So LD is 1 where the members agree and falls as they disagree, and the
    stop probability 1 - LD = 2 sigmoid(K d) - 1 is eq. 4 on the disagreement. `[...] -> [...]`.
    """
    return 2.0 * jax.nn.sigmoid(-gain * d)


def ensemble_stop_probability(d: Array, gain: Array | float = 1.0) -> Array:
    """1 - `ensemble_learning_degree` = tanh(K d / 2), exact near d = 0 where 1 - 2 sigmoid(-K d)
    cancels. `[...] -> [...]`; exactly 0 at d = 0, so members that agree never stop."""
    return jnp.tanh(0.5 * gain * d)


LD_BINS = 10
"""Bins of `ld_histogram`: [0, 0.1), [0.1, 0.2), ..., [0.9, 1]."""


def ld_histogram(ld: Array, weight: Array) -> Array:
    """Weighted count of steps per LD bin (`LD_BINS` equal bins of [0, 1]): `[...] x2 -> [10]`.

    Training records it per iteration over the imagined steps (the paper's Figure 5), a few
    numbers on device instead of every step's LD.
    """
    bins = jnp.clip((ld * LD_BINS).astype(jnp.int32), 0, LD_BINS - 1)
    return (jax.nn.one_hot(bins, LD_BINS) * weight[..., None]).reshape(-1, LD_BINS).sum(axis=0)
