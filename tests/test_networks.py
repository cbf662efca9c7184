"""`ldn_jax.networks`: the MLP's own kernel gradient is JAX's, in the orientation XLA:CPU runs
fast."""

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ldn_jax.networks import MLP

# bit-equality between different programs: XLA's rewrites decide the bits (conftest.py)
pytestmark = pytest.mark.optimized


class JaxMLP(nn.Module):
    """`MLP` with `nn.Dense`'s own `dot_general`, differentiated by JAX."""

    hidden: int
    out: int

    @nn.compact
    def __call__(self, x):
        hidden = nn.relu6(nn.Dense(self.hidden)(x))
        return nn.Dense(self.out)(hidden)


@pytest.mark.parametrize(("inputs", "hidden", "out"), [(4, 200, 2), (6, 200, 4), (300, 8, 1)])
def test_mlp_computes_and_differentiates_as_jax_does(inputs, hidden, out):
    ours = MLP(hidden, out, "relu6", 0.1)
    jaxs = JaxMLP(hidden, out)
    k_init, k_x, k_g = jax.random.split(jax.random.key(inputs), 3)
    params = ours.init(k_init, jnp.zeros((1, inputs)))
    x = jax.random.normal(k_x, (3, 50, inputs))  # two batch axes: rows of a segment
    g = jax.random.normal(k_g, (3, 50, out))

    def vjp(net):
        y, pullback = jax.vjp(lambda p, x: net.apply(p, x), params, x)
        return y, *pullback(g)

    y, d_params, d_x = jax.jit(lambda: vjp(ours))()
    y_jax, d_params_jax, d_x_jax = jax.jit(lambda: vjp(jaxs))()
    np.testing.assert_array_equal(y, y_jax)
    np.testing.assert_array_equal(d_x, d_x_jax)
    for a, b in zip(jax.tree.leaves(d_params), jax.tree.leaves(d_params_jax), strict=True):
        assert a.shape == b.shape
        # The same sums over rows, perhaps added up in another order.
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-5)
    vmapped = jax.jit(jax.vmap(jax.grad(lambda p, x: ours.apply(p, x).sum()), (None, 0)))
    looped = jax.jit(jax.grad(lambda p, x: ours.apply(p, x).sum()))
    batched = jax.tree.leaves(vmapped(params, x))
    for i in range(x.shape[0]):
        for a, b in zip(batched, jax.tree.leaves(looped(params, x[i])), strict=True):
            np.testing.assert_allclose(a[i], b, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("weight_init", ["normal", "fan_in", "torch"])
def test_the_initialisers_give_their_spread_and_the_same_weights_under_jit(weight_init):
    net = MLP(256, 6, "relu", 0.1, layers=2, weight_init=weight_init)
    init = lambda key: net.init(key, jnp.zeros((1, 17)))
    params = init(jax.random.key(0))
    jitted = jax.jit(init)(jax.random.key(0))
    for a, b in zip(jax.tree.leaves(params), jax.tree.leaves(jitted), strict=True):
        np.testing.assert_array_equal(a, b)
    kernels = [layer["kernel"] for layer in params["params"].values()]
    assert [k.shape for k in kernels] == [(17, 256), (256, 256), (256, 6)]
    for kernel in kernels:
        if weight_init != "normal":  # PyTorch's nn.Linear: U(+-1/sqrt(fan_in)), std bound/sqrt(3)
            bound = kernel.shape[0] ** -0.5
            assert np.abs(kernel).max() <= bound and np.abs(kernel).max() > 0.95 * bound
            np.testing.assert_allclose(kernel.std(), bound / np.sqrt(3), rtol=0.1)
        else:
            np.testing.assert_allclose(kernel.std(), 0.1, rtol=0.1)
    for layer, fan_in in zip(params["params"].values(), (17, 256, 256), strict=True):
        if weight_init == "torch":  # PyTorch's biases: U(+-1/sqrt(fan_in)) too
            assert np.abs(layer["bias"]).max() <= fan_in**-0.5
            np.testing.assert_allclose(layer["bias"].std(), fan_in**-0.5 / np.sqrt(3), rtol=0.5)
        else:
            assert not np.any(layer["bias"])


def test_the_orthogonal_initialiser_gives_orthogonal_layers_of_their_gains():
    net = MLP(64, 6, "tanh", 0.1, layers=2, weight_init="orthogonal", out_gain=0.01)
    params = net.init(jax.random.key(0), jnp.zeros((1, 17)))
    jitted = jax.jit(lambda key: net.init(key, jnp.zeros((1, 17))))(jax.random.key(0))
    for a, b in zip(jax.tree.leaves(params), jax.tree.leaves(jitted), strict=True):
        np.testing.assert_array_equal(a, b)
    layers = list(params["params"].values())
    for layer, gain in zip(layers, (2**0.5, 2**0.5, 0.01), strict=True):
        kernel = np.asarray(layer["kernel"], np.float64)
        narrow = min(kernel.shape)  # the narrow side's vectors are orthonormal, times the gain
        gram = kernel.T @ kernel if kernel.shape[0] >= kernel.shape[1] else kernel @ kernel.T
        np.testing.assert_allclose(gram, gain**2 * np.eye(narrow), atol=1e-5 * max(gain**2, 1))
        assert not np.any(layer["bias"])
