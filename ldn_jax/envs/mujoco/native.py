"""MuJoCo's C engine inside jitted programs: `mujoco.rollout` behind one `jax.pure_callback`.

The env state is MuJoCo's full physics state (`mjSTATE_FULLPHYSICS`: time, qpos, qvel, ...)
in float64, carried through JAX as its raw bits (`uint32 [2 * nstate]`: JAX on CPU computes in
float32, and halfcheetah or ant amplify a float32 rounding of the state to O(1) differences
within 200 steps, so the state is never rounded). Beside it the engine returns a float32
`Physics` for the task's observation and reward.

A step is ONE host call for every env in the batch: the callback is registered with
`vmap_method="broadcast_all"`, so vmap over workers, seeds and K hands it `[..., 2 * nstate]`
and `[..., nu]` arrays, and `mujoco.rollout` steps them all (`nstep` = the frame skip) on a
persistent pool with one thread per core.

MuJoCo's constraint solver warm-starts from the previous substep's accelerations. That warm
start is solver state, not physics state; `mujoco.rollout` neither takes it from nor returns
it to the caller per env, so each env step starts the solver cold (within a step the substeps
warm-start as usual). One step then differs from gymnasium's warm-started one at the solver's
tolerance (about 1e-13 in the state); gymnasium stepped with its warm start cleared before
each step equals this engine to the bit.
"""

from __future__ import annotations

import functools
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import rollout as mj_rollout

from ldn_jax.envs.mujoco import model as models
from ldn_jax.envs.mujoco.tasks import Physics, Task

Array = jax.Array


def threads() -> int:
    """Worker threads of the rollout pool: one per core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


@dataclass
class _Pool:
    """One process-wide rollout pool; the lock serialises callers (each device of a sharded
    program calls from its own thread), the pool's threads parallelise each call."""

    rollout: mj_rollout.Rollout
    lock: threading.Lock
    executor: ThreadPoolExecutor
    """For the per-env work outside `mujoco.rollout` (MuJoCo's calls release the GIL)."""


@functools.cache
def _pool() -> _Pool:
    n = threads()
    return _Pool(mj_rollout.Rollout(nthread=n), threading.Lock(), ThreadPoolExecutor(n))


def _to_bits(state: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(state, np.float64).view(np.uint32)


def _from_bits(bits: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(bits, np.uint32).view(np.float64)


class NativeEngine:
    """Steps one task's model in MuJoCo's C library; built once per task (`engine(task)`)."""

    def __init__(self, task: Task):
        self.task = task
        self.model = models.load(task.asset)
        self.nstate = models.state_size(self.model)
        m = self.model
        self.nq, self.nv, self.nu, self.nbody = m.nq, m.nv, m.nu, m.nbody
        self.ncfrc = m.nbody if task.contact_forces else 0
        self.body_ids = models.body_ids(m, task.tracked_bodies)
        self.datas = [mujoco.MjData(m) for _ in range(threads())]
        self.scratch = mujoco.MjData(m)
        self.spec = mujoco.mjtState.mjSTATE_FULLPHYSICS

    # -- shapes --------------------------------------------------------------------------

    def _out_shapes(self, batch: tuple[int, ...]) -> tuple:
        f32 = lambda *shape: jax.ShapeDtypeStruct((*batch, *shape), jnp.float32)
        return (
            jax.ShapeDtypeStruct((*batch, 2 * self.nstate), jnp.uint32),
            f32(self.nq),
            f32(self.nv),
            f32(len(self.body_ids), 3),
            f32(self.ncfrc, 6),
        )

    def _outputs(self, state: np.ndarray, xpos: np.ndarray, cfrc: np.ndarray, batch) -> tuple:
        """Split full states `[B, nstate]` into the callback's outputs, shaped `batch + ...`."""
        qpos = state[:, 1 : 1 + self.nq]
        qvel = state[:, 1 + self.nq : 1 + self.nq + self.nv]
        shape = lambda x, *tail: np.asarray(x, np.float32).reshape(*batch, *tail)
        return (
            _to_bits(state).reshape(*batch, 2 * self.nstate),
            shape(qpos, self.nq),
            shape(qvel, self.nv),
            shape(xpos, len(self.body_ids), 3),
            shape(cfrc, self.ncfrc, 6),
        )

    @staticmethod
    def _physics(out) -> tuple[Array, Physics]:
        bits, qpos, qvel, xpos, cfrc = out
        return bits, Physics(qpos=qpos, qvel=qvel, xpos=xpos, cfrc_ext=cfrc)

    # -- host side -----------------------------------------------------------------------

    def _host_reset(self, qpos: np.ndarray, qvel: np.ndarray) -> tuple:
        """gymnasium's reset: `mj_resetData`, set qpos / qvel, `mj_forward`."""
        batch = qpos.shape[:-1]
        qpos = np.asarray(qpos, np.float64).reshape(-1, self.nq)
        qvel = np.asarray(qvel, np.float64).reshape(-1, self.nv)
        n = qpos.shape[0]
        state = np.empty((n, self.nstate))
        xpos = np.empty((n, len(self.body_ids), 3))
        d, m = self.scratch, self.model
        with _pool().lock:
            for i in range(n):
                mujoco.mj_resetData(m, d)
                d.qpos[:], d.qvel[:] = qpos[i], qvel[i]
                mujoco.mj_forward(m, d)
                mujoco.mj_getState(m, d, state[i], self.spec)
                xpos[i] = d.xpos[self.body_ids]
        return self._outputs(state, xpos, np.zeros((n, self.ncfrc, 6)), batch)

    def _host_step(self, bits: np.ndarray, ctrl: np.ndarray, active: np.ndarray | None = None):
        """Steps the rows of the batch that are `active` (all without it); an inactive row
        keeps its state, with zero body positions and forces."""
        batch = ctrl.shape[:-1]
        state = _from_bits(bits.reshape(-1, 2 * self.nstate))
        ctrl = np.asarray(ctrl, np.float64).reshape(-1, 1, self.nu)
        rows = np.ones(len(state), bool) if active is None else active.reshape(-1)
        after = state.copy()
        xpos = np.zeros((len(state), len(self.body_ids), 3))
        cfrc = np.zeros((len(state), self.ncfrc, 6))
        skip = self.task.frame_skip
        if rows.any():
            live, live_ctrl = state[rows], ctrl[rows]
            pool = _pool()
            with pool.lock:
                states, _ = pool.rollout.rollout(
                    self.model, self.datas, live, live_ctrl, nstep=skip
                )
                last = states[:, -2] if skip > 1 else live
                xpos[rows], cfrc[rows] = self._after_step(last, live_ctrl[:, 0])
            after[rows] = states[:, -1]
        return self._outputs(after, xpos, cfrc, batch)

    def _after_step(self, before_last: np.ndarray, ctrl: np.ndarray) -> tuple:
        """Tracked bodies' `xpos [B, bodies, 3]` and `cfrc_ext [B, nbody, 6]` as gymnasium
        reads them after a step, for the tasks that read them (reacher, ant).

        `mj_step` leaves `xpos` from its last forward pass, which with RK4 (every task but
        halfcheetah) is the last Runge-Kutta stage: no state the rollout returns. So the
        last substep is stepped once more here, from the state before it, followed by
        `mj_rnePostConstraint` as in gymnasium. The rollout's state stays the env state."""
        n = before_last.shape[0]
        xpos = np.zeros((n, len(self.body_ids), 3))
        cfrc = np.zeros((n, self.ncfrc, 6))
        if not (len(self.body_ids) or self.ncfrc):
            return xpos, cfrc
        m = self.model

        def restep(part: int) -> None:
            d = self.datas[part]
            for i in range(part, n, len(self.datas)):
                mujoco.mj_setState(m, d, before_last[i], self.spec)
                d.qacc_warmstart[:] = 0.0
                d.ctrl[:] = ctrl[i]
                mujoco.mj_step(m, d)
                xpos[i] = d.xpos[self.body_ids]
                if self.ncfrc:
                    mujoco.mj_rnePostConstraint(m, d)
                    cfrc[i] = d.cfrc_ext

        list(_pool().executor.map(restep, range(min(n, len(self.datas)))))
        return xpos, cfrc

    # -- JAX side --------------------------------------------------------------------------

    def reset(self, qpos: Array, qvel: Array) -> tuple[Array, Physics]:
        """Engine state `uint32 [2 * nstate]` and `Physics` at the start of an episode."""
        out = jax.pure_callback(
            self._host_reset,
            self._out_shapes(qpos.shape[:-1]),
            qpos,
            qvel,
            vmap_method="broadcast_all",
        )
        return self._physics(out)

    def step(self, bits: Array, ctrl: Array, active: Array | None = None) -> tuple[Array, Physics]:
        """One env step (`frame_skip` substeps) from `bits` with controls `ctrl [nu]`; with
        `active` (bool) false, the physics is not stepped: the state stays, body positions
        and forces are zero (the caller masks the step out)."""
        extra = () if active is None else (active,)
        out = jax.pure_callback(
            self._host_step,
            self._out_shapes(ctrl.shape[:-1]),
            bits,
            ctrl.astype(jnp.float32),
            *extra,
            vmap_method="broadcast_all",
        )
        return self._physics(out)

    def from_state(self, state: np.ndarray) -> Array:
        """Engine state from a float64 full physics state (e.g. a gymnasium env's)."""
        return jnp.asarray(_to_bits(np.asarray(state, np.float64)))

    def full_state(self, bits: Array) -> np.ndarray:
        """The float64 full physics state(s) held in engine state `bits`."""
        return _from_bits(np.asarray(bits)).copy()


@functools.cache
def engine(task: Task) -> NativeEngine:
    return NativeEngine(task)
