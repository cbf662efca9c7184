"""Actor, critic and dynamics-model networks (flax.linen)."""

from __future__ import annotations

from collections.abc import Callable

import flax.linen as nn
import jax
import jax.numpy as jnp

Array = jax.Array

ACTIVATIONS: dict[str, Callable[[Array], Array]] = {
    "linear": lambda x: x,
    "relu": nn.relu,
    "relu6": nn.relu6,
    "tanh": nn.tanh,
    "swish": nn.swish,
}


def normal_init(std: float):
    """flax's `normal(std)` initialiser, kept the same to the bit under `jit` as eagerly.

    The barrier stops XLA from folding `std` into the sampler's own constant factor (its
    sqrt(2) times erfinv), which rounds differently: with it a jitted `Trainer.init_batch`
    gives the weights that op-by-op execution gives.
    """

    def init(key: Array, shape, dtype=jnp.float32) -> Array:
        sample = jax.lax.optimization_barrier(jax.random.normal(key, shape, dtype))
        return sample * jnp.asarray(std, dtype)

    return init


INITS = ("normal", "fan_in", "torch", "orthogonal")
"""Initialisers of the actor-critic's MLPs (`AgentConfig.init`)."""


def kernel_init(init: str, std: float, gain: float = 2**0.5):
    """ "normal": `normal_init(std)`; "fan_in" and "torch": uniform in +-1/sqrt(fan_in)
    (PyTorch's `nn.Linear` default, kaiming-uniform with a = sqrt(5)); "orthogonal": an
    orthogonal matrix times `gain` (SB3's actor-critics: sqrt(2) in the hidden layers)."""
    if init in ("fan_in", "torch"):
        return _uniform(lambda shape: shape[0])
    if init == "orthogonal":
        return nn.initializers.orthogonal(gain)
    return normal_init(std)


def bias_init(init: str, fan_in: int):
    """Zero, except under "torch": uniform in +-1/sqrt(fan_in), as `nn.Linear` starts its
    biases."""
    return _uniform(lambda shape: fan_in) if init == "torch" else nn.initializers.zeros


def _uniform(fan_in_of: Callable[[tuple], int]):
    """Uniform in +-1/sqrt(fan_in), the fan-in read from the parameter's shape."""

    def init(key: Array, shape, dtype=jnp.float32) -> Array:
        # the barrier as in `normal_init`: the same weights jitted as eagerly
        sample = jax.lax.optimization_barrier(jax.random.uniform(key, shape, dtype, -1, 1))
        return sample * jnp.asarray(1.0 / fan_in_of(shape) ** 0.5, dtype)

    return init


@jax.custom_vjp
def _matmul(x: Array, kernel: Array) -> Array:
    """`x @ kernel` over the last axis of `x`, as `nn.Dense` computes it."""
    return jax.lax.dot_general(x, kernel, (((x.ndim - 1,), (0,)), ((), ())))


def _matmul_forward(x: Array, kernel: Array):
    return _matmul(x, kernel), (x, kernel)


def _matmul_backward(residuals, grad: Array):
    """JAX's cotangents of `x @ kernel`, with the kernel's gradient `x^T grad` computed
    with the narrower of its two sides as the rows of the product.

    The kernel's gradient contracts the batch's rows. XLA:CPU runs it several times slower
    when the wide side leads (`[200, 2]` as `h^T g` rather than `(g^T h)^T`; measured in
    docs/logs/benchmarks.md, "The kernel gradient, narrow side first"), and left alone it
    picks either, depending on the program around it; the barrier keeps it from folding the
    transpose back in. The sums are the same, perhaps added in another order
    (tests/test_networks.py). Being a `custom_vjp`, the layer has no forward-mode derivative
    (`jax.jvp`).
    """
    x, kernel = residuals
    inputs, features = kernel.shape
    d_x = jax.lax.dot_general(grad, kernel, (((grad.ndim - 1,), (1,)), ((), ())))
    rows = lambda a: a.reshape(-1, a.shape[-1])
    over_rows = (((0,), (0,)), ((), ()))
    if inputs <= features:
        d_kernel = jax.lax.optimization_barrier(jax.lax.dot_general(rows(x), rows(grad), over_rows))
    else:
        d_kernel = jax.lax.optimization_barrier(
            jax.lax.dot_general(rows(grad), rows(x), over_rows)
        ).T
    return d_x, d_kernel


_matmul.defvjp(_matmul_forward, _matmul_backward)


def dense_dot_general(x: Array, kernel: Array, dimension_numbers, precision=None, **_) -> Array:
    """`nn.Dense`'s `dot_general`, differentiated by `_matmul_backward`."""
    assert dimension_numbers == (((x.ndim - 1,), (0,)), ((), ())), dimension_numbers
    return _matmul(x, kernel)


class MLP(nn.Module):
    """Input -> `layers` hidden layers of `hidden` units -> output (one: the paper's
    "three-layer" net)."""

    hidden: int
    out: int
    activation: str
    init_std: float
    layers: int = 1
    weight_init: str = "normal"
    """One of `INITS`."""
    out_gain: float = 1.0
    """Under "orthogonal": the output layer's gain (SB3: 0.01 for the policy, 1 for the
    value)."""

    @nn.compact
    def __call__(self, x: Array) -> Array:
        dense = lambda size, gain: nn.Dense(  # called on the current `x`: its width is the fan-in
            size,
            kernel_init=kernel_init(self.weight_init, self.init_std, gain),
            bias_init=bias_init(self.weight_init, x.shape[-1]),
            dot_general=dense_dot_general,
        )
        for _ in range(self.layers):
            x = ACTIVATIONS[self.activation](dense(self.hidden, 2**0.5)(x))
        return dense(self.out, self.out_gain)(x)


class DynamicsModel(nn.Module):
    """The paper's model: (s, a) -> s' by one net, then s' -> r by another.

    `a` enters one-hot for discrete actions. With `predict_delta` the first net's output is
    added to `s`, so the reward net still sees the predicted next state.
    """

    obs_size: int
    hidden: int
    activation: str
    init_std: float
    predict_delta: bool

    @nn.compact
    def __call__(self, obs: Array, action: Array) -> tuple[Array, Array]:
        """obs `[..., obs_size]`, action `[..., action_size]` -> (next_obs, reward `[...]`)."""
        mlp = lambda out: MLP(self.hidden, out, self.activation, self.init_std)
        next_obs = mlp(self.obs_size)(jnp.concatenate([obs, action], axis=-1))
        if self.predict_delta:
            next_obs = obs + next_obs
        reward = mlp(1)(next_obs)[..., 0]
        return next_obs, reward


MAX_LOG_VAR = 0.5
"""Where a probabilistic model's upper log-variance bound starts (standardised units)."""

MIN_LOG_VAR = -10.0
"""Where its lower bound starts."""


class GaussianDynamicsModel(nn.Module):
    """A probabilistic model (PETS, MBPO): (s, a) -> a diagonal Gaussian over [s', r].

    One net of `layers` hidden layers predicts the mean of s' - s and of r, and their log
    variance, which is held softly between two learned bounds (`max_log_var`,
    `min_log_var`: parameters, pulled towards each other by the loss's penalty). Weights
    start from flax's default (LeCun normal) initialiser.
    """

    obs_size: int
    hidden: int
    activation: str
    layers: int

    @nn.compact
    def __call__(self, obs: Array, action: Array) -> tuple[Array, Array]:
        """obs `[..., D]`, action `[..., A]` -> (mean, log variance), each `[..., D + 1]`: the
        next observation's (s plus the predicted change) then the reward's."""
        size = self.obs_size + 1
        dense = lambda out: nn.Dense(out, dot_general=dense_dot_general)
        x = jnp.concatenate([obs, action], axis=-1)
        for _ in range(self.layers):
            x = ACTIVATIONS[self.activation](dense(self.hidden)(x))
        out = dense(2 * size)(x)
        mean, log_var = out[..., :size], out[..., size:]
        upper = self.param("max_log_var", nn.initializers.constant(MAX_LOG_VAR), (size,))
        lower = self.param("min_log_var", nn.initializers.constant(MIN_LOG_VAR), (size,))
        log_var = upper - nn.softplus(upper - log_var)
        log_var = lower + nn.softplus(log_var - lower)
        mean = jnp.concatenate([obs + mean[..., :-1], mean[..., -1:]], axis=-1)
        return mean, log_var
