"""MJX (MuJoCo in JAX, for GPUs and TPUs) stepping the same gymnasium models as `native`.

`mujoco.mjx.put_model` takes gymnasium's compiled v5 models as they are; the env state is
MJX's `Data` (float32 on device, its solver warm start included).
"""

from __future__ import annotations

import contextlib
import functools
import io

import jax
import jax.numpy as jnp

from ldn_jax.envs.mujoco import model as models
from ldn_jax.envs.mujoco.tasks import Physics, Task

Array = jax.Array


def _import_mjx():
    # mujoco.mjx prints "Failed to import warp / mujoco_warp" to stdout when NVIDIA's warp is
    # not installed (it is only needed for MJX's warp implementation, which we do not use).
    with contextlib.redirect_stdout(io.StringIO()):
        from mujoco import mjx
    return mjx


class MjxEngine:
    """Steps one task's model through MJX; built once per task (`engine(task)`)."""

    def __init__(self, task: Task):
        self.mjx = _import_mjx()
        self.task = task
        mj_model = models.load(task.asset)
        self.body_ids = models.body_ids(mj_model, task.tracked_bodies)
        # Built while some trace may be running: keep tracers out of the cached model.
        with jax.ensure_compile_time_eval():
            self.model = self.mjx.put_model(mj_model)
            self.empty = self.mjx.make_data(self.model)

    def _physics(self, data) -> Physics:
        if self.task.contact_forces:
            cfrc = data._impl.cfrc_ext  # MJX keeps cfrc_ext with its implementation's fields
        else:
            cfrc = jnp.zeros((0, 6), jnp.float32)
        return Physics(qpos=data.qpos, qvel=data.qvel, xpos=data.xpos[self.body_ids], cfrc_ext=cfrc)

    def reset(self, qpos: Array, qvel: Array):
        data = self.mjx.forward(self.model, self.empty.replace(qpos=qpos, qvel=qvel))
        physics = self._physics(data)
        if self.task.contact_forces:  # zero after a reset, as in MuJoCo (no rnePostConstraint)
            physics = physics.replace(cfrc_ext=jnp.zeros_like(physics.cfrc_ext))
        return data, physics

    def step(self, data, ctrl: Array, active: Array | None = None):
        del active  # every row computes on an accelerator; the caller masks the inactive
        data = data.replace(ctrl=ctrl)
        substep = lambda _, d: self.mjx.step(self.model, d)
        data = jax.lax.fori_loop(0, self.task.frame_skip, substep, data)
        if self.task.contact_forces:
            data = self.mjx.rne_postconstraint(self.model, data)
        return data, self._physics(data)


@functools.cache
def engine(task: Task) -> MjxEngine:
    return MjxEngine(task)
