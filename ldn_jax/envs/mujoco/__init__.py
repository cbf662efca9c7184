"""The paper's six MuJoCo tasks as gymnasium v5 defines them, on either of two physics engines.

One definition per task (`tasks.py`: model file, frame skip, reset, observation, reward and
termination, written once in JAX over the physics state) runs on:
- `native` (`native.py`): MuJoCo's C engine through `mujoco.rollout`, reached from the jitted
  program by one batched host callback per env step. The fast path on CPUs.
- `mjx` (`mjx.py`): MJX, MuJoCo in JAX. The path for GPUs and TPUs.
`auto` picks `native` when JAX's default backend is the CPU and `mjx` otherwise.

Both step gymnasium's own model files, so a policy trained here is evaluated in gymnasium on
the task it learned. Episodes truncate at `EnvParams.max_steps` (the paper's 1,000);
`truncated` is never true together with `terminated`. Each task is gymnasium's
`Task.gymnasium_id` (`Ant-v5`, ...) with its default arguments (`ant-nocfrc`: Ant-v5 with
`include_cfrc_ext_in_observation=False`):

| task              | obs | layout                                         | act |
|-------------------|-----|------------------------------------------------|-----|
| ant               | 105 | qpos[2:] (13), qvel (14), clip(cfrc_ext[1:])   | 8   |
| ant-nocfrc        | 27  | qpos[2:] (13), qvel (14)                       | 8   |
| halfcheetah       | 17  | qpos[1:] (8), qvel (9)                         | 6   |
| hopper            | 11  | qpos[1:] (5), clip(qvel, +-10) (6)             | 3   |
| reacher           | 10  | cos, sin of 2 angles, target xy, 2 velocities, | 2   |
|                   |     | fingertip - target xy                          |     |
| walker2d          | 17  | qpos[1:] (8), clip(qvel, +-10) (9)             | 6   |
| inverted_pendulum | 4   | cart x, pole angle, their velocities           | 1   |

Actions are in [-1, 1] for every task and map linearly onto the actuators' control range
(gymnasium's action space): the identity except inverted_pendulum, whose range is [-3, 3].
"""

from ldn_jax.envs.mujoco.env import (
    BACKEND_CHOICES,
    BACKENDS,
    ContinuousActions,
    EnvParams,
    EnvState,
    MujocoEnv,
    control,
    engine,
    resolve_backend,
)
from ldn_jax.envs.mujoco.model import ModelError
from ldn_jax.envs.mujoco.tasks import TASKS, Physics, Task

__all__ = [
    "BACKENDS",
    "BACKEND_CHOICES",
    "TASKS",
    "ContinuousActions",
    "EnvParams",
    "EnvState",
    "ModelError",
    "MujocoEnv",
    "Physics",
    "Task",
    "control",
    "engine",
    "resolve_backend",
]
