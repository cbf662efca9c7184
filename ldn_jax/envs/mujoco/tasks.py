"""The six MuJoCo tasks, each written once in JAX over the physics state.

A task is gymnasium's v5 env of the same name: its model file and frame skip, its reset
distribution, and its observation, reward and termination as functions of `Physics` (what
either engine reports after a step). Every definition follows gymnasium 1.4's `*_v5.py` with
their default arguments; the comments say where a quantity is easy to get wrong.

Two MuJoCo facts shape the definitions:
- After `mj_step`, `qpos`/`qvel` are the integrated (end of step) values, while body positions
  (`xpos`) are those of the step's last forward pass: before the last substep's integration
  (Euler), or at the last Runge-Kutta stage (RK4). gymnasium reads both; `Physics.xpos` holds
  the tracked bodies' positions as MuJoCo's data holds them after the step, to match.
- `cfrc_ext` (Ant's contact forces) is computed by `mj_rnePostConstraint` after the step, as
  gymnasium's `MujocoEnv` does; it is zero right after a reset.

Observations, rewards and termination tests are also offered as functions of observations
(`is_terminal`, `reward_from_obs`), for the trainer's imagined rollouts.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

Array = jax.Array


@struct.dataclass
class Physics:
    """What a task reads of the simulation after a step or a reset (float32, one env)."""

    qpos: Array
    """`[nq]` generalised positions at the end of the step."""
    qvel: Array
    """`[nv]` generalised velocities at the end of the step."""
    xpos: Array
    """`[len(tracked_bodies), 3]` world positions of the task's tracked bodies' frames, as
    MuJoCo's data holds them after the step (see the module docstring)."""
    cfrc_ext: Array
    """`[nbody, 6]` external contact wrenches per body for tasks that read them, else `[0, 6]`."""


def _ctrl_cost(weight: float, ctrl: Array) -> Array:
    return weight * jnp.sum(jnp.square(ctrl), axis=-1)


def _x_velocity(before: Physics, after: Physics, dt: float) -> Array:
    return (after.qpos[0] - before.qpos[0]) / dt


# -- reset distributions ---------------------------------------------------------------------


def _uniform(key: Array, shape: int, scale: float) -> Array:
    return jax.random.uniform(key, (shape,), jnp.float32, -scale, scale)


def uniform_reset(scale: float) -> Callable:
    """qpos0 + U(-scale, scale) and U(-scale, scale) velocities (hopper, walker2d, pendulum)."""

    def reset(key: Array, qpos0: Array, nv: int) -> tuple[Array, Array]:
        k_qpos, k_qvel = jax.random.split(key)
        return qpos0 + _uniform(k_qpos, qpos0.shape[0], scale), _uniform(k_qvel, nv, scale)

    return reset


def normal_velocity_reset(scale: float) -> Callable:
    """qpos0 + U(-scale, scale) and scale * N(0, 1) velocities (halfcheetah, ant)."""

    def reset(key: Array, qpos0: Array, nv: int) -> tuple[Array, Array]:
        k_qpos, k_qvel = jax.random.split(key)
        qvel = scale * jax.random.normal(k_qvel, (nv,), jnp.float32)
        return qpos0 + _uniform(k_qpos, qpos0.shape[0], scale), qvel

    return reset


def reacher_reset(key: Array, qpos0: Array, nv: int) -> tuple[Array, Array]:
    """Arm angles qpos0 + U(-0.1, 0.1); the target uniform on the disc of radius 0.2 (what
    gymnasium's rejection sampling from the square draws); arm velocities U(-0.005, 0.005),
    the target's zero."""
    k_qpos, k_radius, k_angle, k_qvel = jax.random.split(key, 4)
    qpos = qpos0 + _uniform(k_qpos, qpos0.shape[0], 0.1)
    radius = 0.2 * jnp.sqrt(jax.random.uniform(k_radius, (), jnp.float32))
    angle = jax.random.uniform(k_angle, (), jnp.float32, 0.0, 2.0 * jnp.pi)
    qpos = qpos.at[-2:].set(radius * jnp.stack([jnp.cos(angle), jnp.sin(angle)]))
    qvel = _uniform(k_qvel, nv, 0.005).at[-2:].set(0.0)
    return qpos, qvel


# -- the tasks -----------------------------------------------------------------------------


@dataclass(frozen=True)
class Task:
    """One MuJoCo task as gymnasium v5 defines it (default arguments)."""

    gymnasium_id: str
    asset: str
    """Model file in gymnasium's `envs/mujoco/assets`."""
    frame_skip: int
    """MuJoCo substeps per env step."""
    obs_size: int
    action_size: int
    ctrl_range: tuple[float, float]
    """The actuators' control range; our actions in [-1, 1] map linearly onto it."""
    reset: Callable[[Array, Array, int], tuple[Array, Array]]
    """`(key, qpos0 [nq], nv) -> (qpos [nq], qvel [nv])` of a fresh episode."""
    observation: Callable[[Physics], Array]
    reward: Callable[[Physics, Array, Physics, float], Array]
    """`(before, ctrl, after, dt) -> reward`: gymnasium's reward of the step."""
    terminated: Callable[[Physics], Array]
    is_terminal: Callable[[Array], Array]
    """The termination test on observations `[..., obs_size]` (imagined rollouts)."""
    reward_from_obs: Callable[[Array, Array, Array], Array] | None = None
    """`(obs, ctrl, next_obs) -> reward` where the observation fixes the reward exactly;
    None where it does not (forward velocity: x is not observed)."""
    tracked_bodies: tuple[str, ...] = ()
    """Bodies whose frame positions the task reads: `Physics.xpos`."""
    contact_forces: bool = False
    """The task reads `cfrc_ext` (computed after each step)."""
    step_limit: int = 1000
    """Gymnasium's episode step limit for the task (its `max_episode_steps`)."""
    hidden_qpos: int | None = None
    """Where the observation is the physics state but for the first `hidden_qpos` entries of
    qpos (the x position, which no reward or test reads but as a difference): how many; the
    state rebuilt from an observation puts them at 0 (`MujocoEnv.from_observation`). None: the
    observation is not the state (ant's contact forces, reacher's target)."""
    gymnasium_kwargs: tuple[tuple[str, Any], ...] = ()
    """Arguments of `gymnasium.make(gymnasium_id, ...)` that make gymnasium's env this task
    (none: its defaults)."""


def _never(obs: Array) -> Array:
    return jnp.zeros(obs.shape[:-1], bool)


# HalfCheetah-v5 ------------------------------------------------------------------------------


def _cheetah_obs(p: Physics) -> Array:
    return jnp.concatenate([p.qpos[1:], p.qvel])


def _cheetah_reward(before: Physics, ctrl: Array, after: Physics, dt: float) -> Array:
    return _x_velocity(before, after, dt) - _ctrl_cost(0.1, ctrl)


# Hopper-v5 and Walker2d-v5 ----------------------------------------------------------------
# obs = qpos[1:] (torso z, torso angle, joint angles), clip(qvel, -10, 10). The healthy reward
# (1) is paid only on healthy steps (v5), so the terminating step earns none.


def _walker_obs(p: Physics) -> Array:
    return jnp.concatenate([p.qpos[1:], jnp.clip(p.qvel, -10.0, 10.0)])


def _hopper_healthy_obs(obs: Array) -> Array:
    # gymnasium tests z = qpos[1], angle = qpos[2] and every entry of (qpos[2:], qvel) inside
    # (-100, 100). obs holds qpos[1:] and velocities clipped to +-10, so the velocity part can
    # not be seen in an observation: on obs it tests qpos[2:] only (exact unless |qvel| > 100).
    z, angle = obs[..., 0], obs[..., 1]
    in_range = jnp.all((obs[..., 1:5] > -100.0) & (obs[..., 1:5] < 100.0), axis=-1)
    return in_range & (z > 0.7) & (angle > -0.2) & (angle < 0.2)


def _hopper_healthy(p: Physics) -> Array:
    state = jnp.concatenate([p.qpos[2:], p.qvel])
    in_range = jnp.all((state > -100.0) & (state < 100.0))
    z, angle = p.qpos[1], p.qpos[2]
    return in_range & (z > 0.7) & (angle > -0.2) & (angle < 0.2)


def _walker_healthy_obs(obs: Array) -> Array:
    z, angle = obs[..., 0], obs[..., 1]
    return (z > 0.8) & (z < 2.0) & (angle > -1.0) & (angle < 1.0)


def _walker_healthy(p: Physics) -> Array:
    return _walker_healthy_obs(p.qpos[1:3])


def _locomotion_reward(healthy: Callable[[Physics], Array]) -> Callable:
    def reward(before: Physics, ctrl: Array, after: Physics, dt: float) -> Array:
        alive = healthy(after).astype(jnp.float32)
        return _x_velocity(before, after, dt) + alive - _ctrl_cost(1e-3, ctrl)

    return reward


# Ant-v5 --------------------------------------------------------------------------------------
# obs = qpos[2:] (13), qvel (14), clip(cfrc_ext[1:], -1, 1) flattened (13 bodies x 6 = 78).
# Forward velocity is the torso frame's x over the step as gymnasium reads it
# (`data.body(1).xpos` after the step), not qpos[0].


def _ant_obs(p: Physics) -> Array:
    contact = jnp.clip(p.cfrc_ext[1:], -1.0, 1.0).reshape(-1)
    return jnp.concatenate([p.qpos[2:], p.qvel, contact])


def _ant_obs_without_contact_forces(p: Physics) -> Array:
    return jnp.concatenate([p.qpos[2:], p.qvel])


def _ant_healthy_obs(obs: Array) -> Array:
    z = obs[..., 0]
    return jnp.all(jnp.isfinite(obs), axis=-1) & (z >= 0.2) & (z <= 1.0)


def _ant_healthy(p: Physics) -> Array:
    finite = jnp.all(jnp.isfinite(p.qpos)) & jnp.all(jnp.isfinite(p.qvel))
    return finite & (p.qpos[2] >= 0.2) & (p.qpos[2] <= 1.0)


def _ant_reward(before: Physics, ctrl: Array, after: Physics, dt: float) -> Array:
    x_velocity = (after.xpos[0, 0] - before.xpos[0, 0]) / dt
    contact_cost = 5e-4 * jnp.sum(jnp.square(jnp.clip(after.cfrc_ext, -1.0, 1.0)))
    alive = _ant_healthy(after).astype(jnp.float32)
    return x_velocity + alive - _ctrl_cost(0.5, ctrl) - contact_cost


# Reacher-v5 ----------------------------------------------------------------------------------
# obs = cos q[:2], sin q[:2], target xy (qpos[2:]), arm velocities, (fingertip - target)[:2]
# from the body frames as data holds them after the step. Both bodies sit at the same
# height, so the reward's 3-D distance is the observed 2-D one: exact on observations.


def _reacher_obs(p: Physics) -> Array:
    theta = p.qpos[:2]
    tip_to_target = (p.xpos[0] - p.xpos[1])[:2]
    parts = [jnp.cos(theta), jnp.sin(theta), p.qpos[2:], p.qvel[:2], tip_to_target]
    return jnp.concatenate(parts)


def _reacher_reward(before: Physics, ctrl: Array, after: Physics, dt: float) -> Array:
    del before, dt
    return -jnp.linalg.norm(after.xpos[0] - after.xpos[1]) - _ctrl_cost(1.0, ctrl)


def _reacher_reward_from_obs(obs: Array, ctrl: Array, next_obs: Array) -> Array:
    del obs
    return -jnp.linalg.norm(next_obs[..., 8:10], axis=-1) - _ctrl_cost(1.0, ctrl)


# InvertedPendulum-v5 -------------------------------------------------------------------------
# obs = (cart x, pole angle, their velocities). Terminates when the pole leans more than 0.2
# rad (or anything is non-finite); v5 pays 1 on every step except the terminating one.


def _pendulum_obs(p: Physics) -> Array:
    return jnp.concatenate([p.qpos, p.qvel])


def _pendulum_is_terminal(obs: Array) -> Array:
    return ~jnp.all(jnp.isfinite(obs), axis=-1) | (jnp.abs(obs[..., 1]) > 0.2)


def _pendulum_reward_from_obs(obs: Array, ctrl: Array, next_obs: Array) -> Array:
    del obs, ctrl
    return 1.0 - _pendulum_is_terminal(next_obs).astype(jnp.float32)


TASKS: dict[str, Task] = {
    "ant": Task(
        gymnasium_id="Ant-v5",
        asset="ant.xml",
        frame_skip=5,
        obs_size=105,
        action_size=8,
        ctrl_range=(-1.0, 1.0),
        reset=normal_velocity_reset(0.1),
        observation=_ant_obs,
        reward=_ant_reward,
        terminated=lambda p: ~_ant_healthy(p),
        is_terminal=lambda obs: ~_ant_healthy_obs(obs),
        tracked_bodies=("torso",),
        contact_forces=True,
    ),
    "halfcheetah": Task(
        gymnasium_id="HalfCheetah-v5",
        asset="half_cheetah.xml",
        frame_skip=5,
        obs_size=17,
        action_size=6,
        ctrl_range=(-1.0, 1.0),
        reset=normal_velocity_reset(0.1),
        observation=_cheetah_obs,
        reward=_cheetah_reward,
        terminated=lambda p: jnp.zeros((), bool),
        is_terminal=_never,
        hidden_qpos=1,
    ),
    "hopper": Task(
        gymnasium_id="Hopper-v5",
        asset="hopper.xml",
        frame_skip=4,
        obs_size=11,
        action_size=3,
        ctrl_range=(-1.0, 1.0),
        reset=uniform_reset(5e-3),
        observation=_walker_obs,
        reward=_locomotion_reward(_hopper_healthy),
        terminated=lambda p: ~_hopper_healthy(p),
        is_terminal=lambda obs: ~_hopper_healthy_obs(obs),
        hidden_qpos=1,
    ),
    "reacher": Task(
        gymnasium_id="Reacher-v5",
        asset="reacher.xml",
        frame_skip=2,
        obs_size=10,
        action_size=2,
        ctrl_range=(-1.0, 1.0),
        reset=reacher_reset,
        observation=_reacher_obs,
        reward=_reacher_reward,
        terminated=lambda p: jnp.zeros((), bool),
        is_terminal=_never,
        reward_from_obs=_reacher_reward_from_obs,
        tracked_bodies=("fingertip", "target"),
        step_limit=50,
    ),
    "walker2d": Task(
        gymnasium_id="Walker2d-v5",
        asset="walker2d_v5.xml",
        frame_skip=4,
        obs_size=17,
        action_size=6,
        ctrl_range=(-1.0, 1.0),
        reset=uniform_reset(5e-3),
        observation=_walker_obs,
        reward=_locomotion_reward(_walker_healthy),
        terminated=lambda p: ~_walker_healthy(p),
        is_terminal=lambda obs: ~_walker_healthy_obs(obs),
        hidden_qpos=1,
    ),
    "inverted_pendulum": Task(
        gymnasium_id="InvertedPendulum-v5",
        asset="inverted_pendulum.xml",
        frame_skip=2,
        obs_size=4,
        action_size=1,
        ctrl_range=(-3.0, 3.0),
        reset=uniform_reset(0.01),
        observation=_pendulum_obs,
        reward=lambda before, ctrl, after, dt: _pendulum_reward_from_obs(
            None, ctrl, _pendulum_obs(after)
        ),
        terminated=lambda p: _pendulum_is_terminal(_pendulum_obs(p)),
        is_terminal=_pendulum_is_terminal,
        reward_from_obs=_pendulum_reward_from_obs,
        hidden_qpos=0,
    ),
}
"""Our names -> gymnasium v5's definitions."""

# Ant-v5 without the contact forces in the observation (27 dimensions), as Ant-v4's default has
# it and as gym's Ant-v3 under MuJoCo >= 2.0 had it in effect (its contact forces read all
# zero): the task rl-baselines3-zoo's Ant figure measured. The reward still charges v5's
# contact cost.
TASKS["ant-nocfrc"] = replace(
    TASKS["ant"],
    obs_size=27,
    observation=_ant_obs_without_contact_forces,
    hidden_qpos=2,
    gymnasium_kwargs=(("include_cfrc_ext_in_observation", False),),
)
