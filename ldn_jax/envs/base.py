"""The environment protocol every env in this project follows.

State and params are kept apart (as in gymnax) so that params can be vmapped, and
`terminated` is kept apart from `truncated`: a terminated transition has no future value,
a truncated one does and must be bootstrapped.
"""

from __future__ import annotations

from typing import Any, Protocol

import jax

Array = jax.Array


class Env(Protocol):
    """A pure, jittable environment.

    Every method is a pure function of its arguments; nothing is stored on the object
    between calls, so one instance serves every vmapped seed and worker.
    """

    def reset(self, key: Array, params: Any) -> tuple[Array, Any]:
        """Return `(obs, state)` for a fresh episode."""
        ...

    def step(
        self, key: Array, state: Any, action: Array, params: Any
    ) -> tuple[Array, Any, Array, Array, Array, dict]:
        """Return `(obs, state, reward, terminated, truncated, info)`.

        `terminated` and `truncated` are never both true: a transition that reaches
        the step limit and a terminal state at once counts as terminated.
        """
        ...

    def is_terminal(self, obs: Array, params: Any) -> Array:
        """Termination test as a pure function of observations `[..., obs_size]`.

        Imagined rollouts call it on predicted observations.
        """
        ...

    def reward(self, obs: Array, action: Array, next_obs: Array, params: Any) -> Array | None:
        """The reward `[...]` of transitions as a pure function of observations and actions
        `[..., A]` (an imagined rollout can use it instead of the model's); None where the
        observations do not determine it (see `exact_reward`)."""
        ...

    def exact_reward(self, params: Any) -> bool:
        """Whether `reward` is exact for these params (known before tracing)."""
        ...

    def with_backend(self, params: Any, backend: str) -> Any:
        """Params that step the physics on `backend` ("auto" picks by platform); an env
        with a single engine returns `params` as they are."""
        ...

    def observation_size(self, params: Any) -> int:
        """Length of the flat observation vector."""
        ...

    def action_spec(self, params: Any) -> ActionSpec:
        """What actions look like: discrete count or continuous bounds."""
        ...


# Optional: `step_active(key, state, action, params, active) -> step's outputs`, `step` for a
# worker whose step counts only where `active` (bool): an env whose physics is costly per
# worker (the native MuJoCo engine) skips it for inactive workers, whose outputs the caller
# masks out. The trainer uses it for workers whose episode has ended and `step` otherwise.

# Optional: `from_observation(obs, params) -> state`, the state an observation is of, for envs
# whose observation is their whole state (CartPole). The oracle stop steps the real env
# from imagined observations with it; envs without it refuse that rule.


class ActionSpec(Protocol):
    discrete: bool
    size: int
    """Number of actions (discrete) or action dimensions (continuous)."""
