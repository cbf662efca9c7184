"""CartPole v0 / v1 / v2 as one pure-JAX env.

Physics, constants, reset distribution and termination follow gymnasium's
`CartPoleEnv` (Barto, Sutton & Anderson 1983 with Euler integration). The versions differ
only in `EnvParams`: the episode step limit and the table of forces an action index selects.
v2 is the paper's custom variant with five forces and 1,000 steps.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
from flax import struct

Array = jax.Array

# gymnasium's constants; kept module-level because no experiment varies them.
GRAVITY = 9.8
MASS_CART = 1.0
MASS_POLE = 0.1
TOTAL_MASS = MASS_CART + MASS_POLE
HALF_LENGTH = 0.5  # gymnasium calls it `length`: half the pole's length
POLE_MASS_LENGTH = MASS_POLE * HALF_LENGTH
TAU = 0.02
X_THRESHOLD = 2.4
THETA_THRESHOLD = 12 * 2 * jnp.pi / 360
RESET_BOUND = 0.05


@struct.dataclass
class EnvParams:
    """Per-version parameters. Both are static: they fix scan lengths and the action count."""

    max_steps: int = struct.field(pytree_node=False, default=500)
    """Episode step limit; reaching it truncates (never terminates) the episode."""
    forces: tuple[float, ...] = struct.field(pytree_node=False, default=(-10.0, 10.0))
    """Force (N) applied to the cart for each action index."""


@struct.dataclass
class EnvState:
    physics: Array
    """`[4]` (x, x_dot, theta, theta_dot), float32."""
    time: Array
    """Steps taken in this episode, int32."""


@dataclass(frozen=True)
class DiscreteActions:
    size: int
    discrete: bool = True
    forces: tuple[float, ...] = ()
    """The force each action index applies (a model can take actions as forces)."""


def is_terminal(obs: Array) -> Array:
    """True where the cart left the track or the pole fell, for obs `[..., 4]`."""
    x, theta = obs[..., 0], obs[..., 2]
    return (jnp.abs(x) > X_THRESHOLD) | (jnp.abs(theta) > THETA_THRESHOLD)


def dynamics(physics: Array, force: Array) -> Array:
    """One Euler step of the cart-pole equations of motion, for physics `[4]`."""
    x, x_dot, theta, theta_dot = physics[0], physics[1], physics[2], physics[3]
    cos, sin = jnp.cos(theta), jnp.sin(theta)
    temp = (force + POLE_MASS_LENGTH * theta_dot**2 * sin) / TOTAL_MASS
    theta_acc = (GRAVITY * sin - cos * temp) / (
        HALF_LENGTH * (4.0 / 3.0 - MASS_POLE * cos**2 / TOTAL_MASS)
    )
    x_acc = temp - POLE_MASS_LENGTH * theta_acc * cos / TOTAL_MASS
    # gymnasium's default "euler": positions advance with the old velocities.
    return jnp.stack(
        [
            x + TAU * x_dot,
            x_dot + TAU * x_acc,
            theta + TAU * theta_dot,
            theta_dot + TAU * theta_acc,
        ]
    )


class CartPole:
    """The CartPole family behind the `ldn_jax.envs.base.Env` protocol."""

    def reset(self, key: Array, params: EnvParams) -> tuple[Array, EnvState]:
        physics = jax.random.uniform(key, (4,), jnp.float32, -RESET_BOUND, RESET_BOUND)
        return physics, EnvState(physics=physics, time=jnp.zeros((), jnp.int32))

    def step(
        self, key: Array, state: EnvState, action: Array, params: EnvParams
    ) -> tuple[Array, EnvState, Array, Array, Array, dict]:
        del key  # deterministic dynamics
        force = jnp.asarray(params.forces, jnp.float32)[action]
        physics = dynamics(state.physics, force)
        time = state.time + 1
        terminated = is_terminal(physics)
        truncated = (time >= params.max_steps) & ~terminated
        # gymnasium pays +1 on every step, the terminating one included.
        reward = jnp.ones((), jnp.float32)
        return physics, EnvState(physics=physics, time=time), reward, terminated, truncated, {}

    def is_terminal(self, obs: Array, params: EnvParams) -> Array:
        del params
        return is_terminal(obs)

    def reward(self, obs: Array, action: Array, next_obs: Array, params: EnvParams) -> Array:
        del action, next_obs, params
        return jnp.ones(obs.shape[:-1], jnp.float32)  # +1 per step, the last one included

    def exact_reward(self, params: EnvParams) -> bool:
        return True

    def with_backend(self, params: EnvParams, backend: str) -> EnvParams:
        del backend  # pure-JAX physics, one engine
        return params

    def observation_size(self, params: EnvParams) -> int:
        return 4

    def action_spec(self, params: EnvParams) -> DiscreteActions:
        return DiscreteActions(size=len(params.forces), forces=tuple(params.forces))

    def from_observation(self, obs: Array, params: EnvParams) -> EnvState:
        """The state whose observation is `obs [4]` (CartPole's observation is its physics),
        at time 0: the real env stepped from an imagined state (the oracle stop, the
        calibration's one-step error)."""
        del params
        return EnvState(physics=obs, time=jnp.zeros((), jnp.int32))
