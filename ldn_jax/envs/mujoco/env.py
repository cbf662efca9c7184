"""The MuJoCo env behind the env protocol: one class for every task, on the engine its
params name (the package's docstring describes the tasks and the engines)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from ldn_jax.envs.mujoco.tasks import TASKS, Physics, Task

Array = jax.Array

BACKENDS = ("native", "mjx")
"""Physics engines; `auto` resolves to one of them (`resolve_backend`)."""

BACKEND_CHOICES = ("auto", *BACKENDS)


def resolve_backend(backend: str) -> str:
    """`auto` -> `native` on CPU, `mjx` on GPU/TPU; other names are checked and returned."""
    if backend not in BACKEND_CHOICES:
        raise ValueError(
            f"unknown backend {backend!r}; valid backends: {', '.join(BACKEND_CHOICES)}"
        )
    if backend == "auto":
        return "native" if jax.default_backend() == "cpu" else "mjx"
    return backend


def engine(task: str, backend: str):
    """The engine stepping `task` on `backend`, built once per process. Raises ValueError (one
    line) for an unknown task or backend, `ModelError` when mujoco cannot load the model."""
    if task not in TASKS:
        raise ValueError(f"unknown MuJoCo task {task!r}; valid tasks: {', '.join(TASKS)}")
    backend = resolve_backend(backend)
    if backend == "native":
        from ldn_jax.envs.mujoco import native

        return native.engine(TASKS[task])
    from ldn_jax.envs.mujoco import mjx

    return mjx.engine(TASKS[task])


@struct.dataclass
class EnvParams:
    """Which task, on which engine, for how long. All static: one instance serves every
    vmapped worker and seed, and each distinct value compiles its own program."""

    task: str = struct.field(pytree_node=False, default="inverted_pendulum")
    """One of `TASKS`."""
    backend: str = struct.field(pytree_node=False, default="auto")
    """One of `BACKEND_CHOICES`."""
    max_steps: int = struct.field(pytree_node=False, default=1000)
    """Episode step limit; reaching it truncates (never terminates) the episode."""


@struct.dataclass
class EnvState:
    engine: Any
    """The engine's state: native, MuJoCo's float64 full physics state as `uint32` bits;
    mjx, MJX's `Data`."""
    physics: Physics
    """What the task read after the last step (the reward needs the step's start)."""
    time: Array
    """Steps taken in this episode, int32."""


@dataclass(frozen=True)
class ContinuousActions:
    size: int
    low: tuple[float, ...]
    high: tuple[float, ...]
    discrete: bool = False


class MujocoEnv:
    """Any of `TASKS` behind the `ldn_jax.envs.base.Env` protocol; the task lives in `EnvParams`."""

    def reset(self, key: Array, params: EnvParams) -> tuple[Array, EnvState]:
        task, sim = TASKS[params.task], engine(params.task, params.backend)
        qpos0 = jnp.asarray(_qpos0(params.task), jnp.float32)
        qpos, qvel = task.reset(key, qpos0, _nv(params.task))
        state, physics = sim.reset(qpos, qvel)
        env_state = EnvState(engine=state, physics=physics, time=jnp.zeros((), jnp.int32))
        return task.observation(physics), env_state

    def step(
        self, key: Array, state: EnvState, action: Array, params: EnvParams
    ) -> tuple[Array, EnvState, Array, Array, Array, dict]:
        return self.step_active(key, state, action, params, None)

    def step_active(
        self, key: Array, state: EnvState, action: Array, params: EnvParams, active: Array | None
    ) -> tuple[Array, EnvState, Array, Array, Array, dict]:
        """`step` for a worker whose step counts only where `active` (bool): the native
        engine leaves the physics of an inactive worker unstepped (its outputs are finite
        and meaningless; the caller masks them out), MJX computes every worker."""
        del key  # deterministic physics
        task, sim = TASKS[params.task], engine(params.task, params.backend)
        ctrl = control(task, action)
        engine_state, physics = sim.step(state.engine, ctrl, active)
        reward = task.reward(state.physics, ctrl, physics, _dt(params.task))
        terminated = task.terminated(physics)
        time = state.time + 1
        truncated = (time >= params.max_steps) & ~terminated
        new_state = EnvState(engine=engine_state, physics=physics, time=time)
        return (
            task.observation(physics),
            new_state,
            reward.astype(jnp.float32),
            terminated,
            truncated,
            {},
        )

    def observes_state(self, params: EnvParams) -> bool:
        """Whether `from_observation` can rebuild the task's state from an observation."""
        return TASKS[params.task].hidden_qpos is not None

    def from_observation(self, obs: Array, params: EnvParams) -> EnvState:
        """The state whose observation is `obs [O]`, at time 0, with the qpos entries the
        observation leaves out (the x position) at 0: the real env stepped from an imagined
        state (the oracle stop, `model.world` "true"). hopper's and walker2d's velocities
        are clipped to +-10 in the observation, so there it is exact below that. Raises
        ValueError (at trace time) for a task whose observation is not its state."""
        task, sim = TASKS[params.task], engine(params.task, params.backend)
        if task.hidden_qpos is None:
            raise ValueError(f"{params.task}'s observation is not its state")
        nq, nv, hidden = len(_qpos0(params.task)), _nv(params.task), task.hidden_qpos
        qpos = jnp.concatenate([jnp.zeros(hidden, obs.dtype), obs[: nq - hidden]])
        state, physics = sim.reset(qpos, obs[nq - hidden : nq - hidden + nv])
        return EnvState(engine=state, physics=physics, time=jnp.zeros((), jnp.int32))

    def is_terminal(self, obs: Array, params: EnvParams) -> Array:
        return TASKS[params.task].is_terminal(obs)

    def reward(self, obs: Array, action: Array, next_obs: Array, params: EnvParams) -> Array | None:
        """Reward `[...]` of transitions `obs [..., O]`, `action [..., A]`, `next_obs [..., O]`
        where the task's reward is an exact function of them; None otherwise (decided at
        trace time from the static task)."""
        task = TASKS[params.task]
        if task.reward_from_obs is None:
            return None
        return task.reward_from_obs(obs, control(task, action), next_obs)

    def exact_reward(self, params: EnvParams) -> bool:
        return TASKS[params.task].reward_from_obs is not None

    def with_backend(self, params: EnvParams, backend: str) -> EnvParams:
        return params.replace(backend=resolve_backend(backend))

    def observation_size(self, params: EnvParams) -> int:
        return TASKS[params.task].obs_size

    def action_spec(self, params: EnvParams) -> ContinuousActions:
        size = TASKS[params.task].action_size
        return ContinuousActions(size=size, low=(-1.0,) * size, high=(1.0,) * size)


def control(task: Task, action: Array) -> Array:
    """Our action in [-1, 1] -> the actuators' control (gymnasium's action).

    A non-finite action (a diverged policy) is applied as zero control: MuJoCo would print a
    warning for every such step and reset its state, and MJX would carry the NaN on. The
    return of such a step is still non-finite where the reward reads the action, and the
    trainer's guard reports the divergence either way.
    """
    action = jnp.where(jnp.isfinite(action), action, 0.0)
    low, high = task.ctrl_range
    if (low, high) == (-1.0, 1.0):
        return action
    return low + (action + 1.0) * (0.5 * (high - low))


def _model(task: str):
    from ldn_jax.envs.mujoco import model

    return model.load(TASKS[task].asset)


def _qpos0(task: str):
    return _model(task).qpos0


def _nv(task: str) -> int:
    return _model(task).nv


def _dt(task: str) -> float:
    """Seconds per env step, as gymnasium's `env.dt` (model timestep x frame skip)."""
    return float(_model(task).opt.timestep) * TASKS[task].frame_skip
