"""The paper's six MuJoCo tasks through brax's environments, behind `envs.base.Env`.

`brax.envs.get_environment(task, backend=...)` supplies physics, observations, rewards and
brax's own `done`; this module adds what the protocol needs and brax leaves out:

- a step counter in our state, so episodes truncate at `EnvParams.max_steps` (1,000 in the
  paper) and `truncated` is never true together with `terminated`. brax's EpisodeWrapper /
  AutoResetWrapper are not used: they fold truncation into `done`.
- each task's termination test as a pure, batched function of the observation, so imagined
  rollouts can test a model's predicted observation (`MujocoEnv.is_terminal`);
- the reward as a function of `(obs, action, next_obs)` where it is one exactly
  (`MujocoEnv.reward`; None elsewhere, so the trainer learns the reward).

brax envs are unbatched: `reset(rng)` takes one key and `step(state, action)` one action
`[action_size]`; obs is `[obs_size]`, reward and done are float32 scalars (done is 1.0 / 0.0).
Batches come from `jax.vmap`, which the MJX pipeline supports.

Observation sizes, as measured (all with brax's default
`exclude_current_positions_from_observation=True`, which drops qpos x, and for ant x and y):

| task              | obs | layout                                                         | act |
|-------------------|-----|----------------------------------------------------------------|-----|
| ant               | 27  | qpos[2:] (13: torso z, quaternion, 8 joints), qvel (14);       | 8   |
|                   |     | brax's Ant has no contact forces (`use_contact_forces=False`)  |     |
|                   |     | and raises if asked, unlike gym's 111-entry Ant                |     |
| halfcheetah       | 17  | qpos[1:] (8), qvel (9)                                         | 6   |
| hopper            | 11  | torso z, qpos[2:] (4 angles), clip(qvel, -10, 10) (6)          | 3   |
| reacher           | 11  | cos q[:2], sin q[:2], target xy, fingertip vel xy, tip-target  | 2   |
| walker2d          | 17  | torso z, qpos[2:] (7 angles), clip(qvel, -10, 10) (9)          | 6   |
| inverted_pendulum | 4   | cart x, pole angle, their velocities                           | 1   |

Actions are in [-1, 1] for every task: the actuators' control range (clipped by the physics),
except inverted_pendulum, whose env maps [-1, 1] onto its [-3, 3] control range.

Termination, and how far the observation determines it (brax's `done`, healthy ranges as in
brax 0.14.2's sources):
- hopper: unhealthy unless 0.7 < torso z (obs[0]), |torso angle| (obs[1]) < 0.2 and every entry
  of concat(qpos[2:], qvel) within (-100, 100). obs clips velocities to +-10, so the velocity
  part of the range test cannot be seen in a real observation; we apply the range test to
  obs[1:], which agrees with brax except when a true velocity exceeds 100.
- walker2d: 0.8 < torso z (obs[0]) < 2 and -1 < torso angle (obs[1]) < 1. Exact.
- ant: 0.2 <= torso z <= 1, where brax reads z from the body transforms and obs[0] is the free
  joint's z. Under "generalized" the two are the same number. Under "mjx" the body transforms
  are MuJoCo's `xpos`, computed before the last physics substep's integration, so brax's z lags
  obs[0] by one substep (up to 0.05 in random rollouts): we undo MuJoCo's Euler step,
  z = obs[0] - h * obs[15] (obs[15] is the free joint's z velocity, h = 0.01 s): agrees with
  brax to 6e-8. Under "generalized" and "positional" obs[0] equals brax's z (checked on random
  rollouts).
- inverted_pendulum: |pole angle| (obs[1]) > 0.2. Exact.
- halfcheetah, reacher: never terminate.

Rewards that are functions of `(obs, action, next_obs)`: inverted_pendulum (1 on every step,
the terminating one included) and reacher (-|tip - target| of next_obs - |action|^2) are
exact. halfcheetah, hopper, walker2d and ant pay forward velocity measured as the torso's x
displacement over the step, and x is not observed (qvel is the end-of-step velocity, not the
mean), so they return None.

Backends (`EnvParams.backend`): "mjx" (the paper's setup via MJX), or brax's own
"generalized" and "positional". brax changes the model for some backends (positional:
shorter timestep, more frames, other gears for ant, halfcheetah, reacher, inverted_pendulum;
mjx: a cheaper Newton solver for ant), so returns differ across backends.

Throughput on the shared 2-core CPU (load ~3.5 from other jobs, so +-30%), 2026-11-22:
jit(vmap) of a 100-step scan, 64 envs, random actions, every obs consumed
(`bench/mujoco_envs.py`); env steps per second, compile seconds in brackets:

| task              | mjx           | generalized   | positional    |
|-------------------|---------------|---------------|---------------|
| inverted_pendulum | 60,068 (11 s) | 73,290 (10 s) | 55,623 (12 s) |
| halfcheetah       | 1,189 (20 s)  | 2,969 (19 s)  | 2,854 (27 s)  |

On CPU "generalized" is the faster choice for halfcheetah (2.5x). positional halfcheetah
integrates 16 substeps of 3.1 ms per env step where the others take 5 of 10 ms.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

Array = jax.Array

BACKENDS = ("mjx", "generalized", "positional")


@struct.dataclass
class EnvParams:
    """Which task, through which physics, for how long. All static: one instance serves
    every vmapped worker and seed, and each distinct value compiles its own program."""

    task: str = struct.field(pytree_node=False, default="inverted_pendulum")
    """brax environment name: one of `TASKS`."""
    backend: str = struct.field(pytree_node=False, default="mjx")
    """brax physics pipeline: one of `BACKENDS`."""
    max_steps: int = struct.field(pytree_node=False, default=1000)
    """Episode step limit; reaching it truncates (never terminates) the episode."""


@struct.dataclass
class EnvState:
    brax: Any
    """brax's `State` for one env (physics, obs, reward, done, metrics)."""
    time: Array
    """Steps taken in this episode, int32."""


@dataclass(frozen=True)
class ContinuousActions:
    size: int
    low: tuple[float, ...]
    high: tuple[float, ...]
    discrete: bool = False


def _never(obs: Array, params: EnvParams) -> Array:
    del params
    return jnp.zeros(obs.shape[:-1], bool)


def hopper_is_terminal(obs: Array, params: EnvParams) -> Array:
    """brax Hopper's unhealthy test on obs `[..., 11]` (see the module docstring)."""
    del params
    z, angle = obs[..., 0], obs[..., 1]
    in_range = jnp.all((obs[..., 1:] > -100.0) & (obs[..., 1:] < 100.0), axis=-1)
    healthy = in_range & (z > 0.7) & (z < jnp.inf) & (angle > -0.2) & (angle < 0.2)
    return ~healthy


def walker2d_is_terminal(obs: Array, params: EnvParams) -> Array:
    """brax Walker2d's unhealthy test on obs `[..., 17]`."""
    del params
    z, angle = obs[..., 0], obs[..., 1]
    return ~((z > 0.8) & (z < 2.0) & (angle > -1.0) & (angle < 1.0))


ANT_MJX_SUBSTEP = 0.01
"""Physics timestep (s) of brax's Ant on the mjx backend (5 substeps per env step)."""


def ant_is_terminal(obs: Array, params: EnvParams) -> Array:
    """brax Ant's unhealthy test on obs `[..., 27]`: torso z outside [0.2, 1]."""
    z = obs[..., 0]
    if params.backend == "mjx":
        z = z - ANT_MJX_SUBSTEP * obs[..., 15]  # brax's z: before the last substep
    return (z < 0.2) | (z > 1.0)


def inverted_pendulum_is_terminal(obs: Array, params: EnvParams) -> Array:
    """brax InvertedPendulum's done on obs `[..., 4]`: the pole leans more than 0.2 rad."""
    del params
    return jnp.abs(obs[..., 1]) > 0.2


def inverted_pendulum_reward(obs: Array, action: Array, next_obs: Array) -> Array:
    del obs, action
    return jnp.ones(next_obs.shape[:-1], jnp.float32)


def reacher_reward(obs: Array, action: Array, next_obs: Array) -> Array:
    """Distance of the fingertip to the target after the step, plus the control cost."""
    del obs
    distance = jnp.sqrt(jnp.sum(jnp.square(next_obs[..., -3:]), axis=-1))
    return -distance - jnp.sum(jnp.square(action), axis=-1)


RewardFn = Callable[[Array, Array, Array], Array]


@dataclass(frozen=True)
class Task:
    obs_size: int
    action_size: int
    is_terminal: Callable[[Array, EnvParams], Array]
    reward: RewardFn | None
    """Exact reward from `(obs, action, next_obs)`, or None where the obs does not fix it."""


TASKS: dict[str, Task] = {
    "ant": Task(27, 8, ant_is_terminal, None),
    "halfcheetah": Task(17, 6, _never, None),
    "hopper": Task(11, 3, hopper_is_terminal, None),
    "reacher": Task(11, 2, _never, reacher_reward),
    "walker2d": Task(17, 6, walker2d_is_terminal, None),
    "inverted_pendulum": Task(4, 1, inverted_pendulum_is_terminal, inverted_pendulum_reward),
}


@functools.cache
def brax_env(task: str, backend: str) -> Any:
    """brax's env for `task` on `backend`, built once per process (loading the model is slow)."""
    if task not in TASKS:
        raise ValueError(f"unknown MuJoCo task {task!r}; valid tasks: {', '.join(TASKS)}")
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; valid backends: {', '.join(BACKENDS)}")
    from brax import envs as brax_envs  # slow import: only when a MuJoCo task is used

    # The first call usually comes while jit traces reset or step; building the model then
    # would store that trace's tracers in the cached env, and every later trace would fail.
    with jax.ensure_compile_time_eval():
        return brax_envs.get_environment(task, backend=backend)


def _canonical(state: Any) -> Any:
    # Some brax envs return Python floats for reward/done (inverted_pendulum pays 1.0); fix
    # them as float32 scalars so the state has one type across reset and step (scan carries).
    return state.replace(
        reward=jnp.asarray(state.reward, jnp.float32), done=jnp.asarray(state.done, jnp.float32)
    )


class MujocoEnv:
    """Any of `TASKS` behind the `envs.base.Env` protocol; the task lives in `EnvParams`."""

    def reset(self, key: Array, params: EnvParams) -> tuple[Array, EnvState]:
        state = _canonical(brax_env(params.task, params.backend).reset(key))
        return state.obs, EnvState(brax=state, time=jnp.zeros((), jnp.int32))

    def step(
        self, key: Array, state: EnvState, action: Array, params: EnvParams
    ) -> tuple[Array, EnvState, Array, Array, Array, dict]:
        del key  # deterministic physics
        brax_state = _canonical(brax_env(params.task, params.backend).step(state.brax, action))
        time = state.time + 1
        terminated = brax_state.done > 0.5
        truncated = (time >= params.max_steps) & ~terminated
        new_state = EnvState(brax=brax_state, time=time)
        return brax_state.obs, new_state, brax_state.reward, terminated, truncated, {}

    def is_terminal(self, obs: Array, params: EnvParams) -> Array:
        return TASKS[params.task].is_terminal(obs, params)

    def reward(self, obs: Array, action: Array, next_obs: Array, params: EnvParams) -> Array | None:
        """Reward `[...]` of transitions `obs [..., O]`, `action [..., A]`, `next_obs [..., O]`
        where the task's reward is an exact function of them; None otherwise (decided at
        trace time from the static task)."""
        reward_fn = TASKS[params.task].reward
        return None if reward_fn is None else reward_fn(obs, action, next_obs)

    def observation_size(self, params: EnvParams) -> int:
        return TASKS[params.task].obs_size

    def action_spec(self, params: EnvParams) -> ContinuousActions:
        size = TASKS[params.task].action_size
        return ContinuousActions(size=size, low=(-1.0,) * size, high=(1.0,) * size)
