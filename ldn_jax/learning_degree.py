"""The learning degree (eq. 3-6) and the stop draw that ends imagined episodes.

LD measures how far the trained model M1 has moved from its frozen initial copy M0 on an
input: near 0 where M1 has learned nothing (imagination stops at once), towards 1 where it has
learned much (imagination goes on).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

Array = jax.Array


def deviation(pred_m1: Array, pred_m0: Array) -> Array:
    """Eq. 3: sigma2 = 1/2 (M1 - M0)^2, reduced by the mean over output dims.

    `[..., D], [..., D] -> [...]`.
    """
    return 0.5 * jnp.mean(jnp.square(pred_m1 - pred_m0), axis=-1)


def learning_degree(sigma2: Array, k: Array | float = 1.0) -> Array:
    """Eq. 4 and 6: LD = 2 sigmoid(K sigma2) - 1, in [0, 1) for sigma2 >= 0."""
    return 2.0 * jax.nn.sigmoid(k * sigma2) - 1.0


def stop_draw(key: Array, ld: Array) -> Array:
    """Eq. 5: stop with probability 1 - LD (u ~ U[0, 1), stop when u < 1 - LD)."""
    return jax.random.uniform(key, ld.shape) < 1.0 - ld
