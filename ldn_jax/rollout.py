"""One episode per worker, in segments of n steps with a learner update after each.

The same function plays real episodes (the world is the env) and imagined ones (the world is
M1): a world is a pure `step(key, world_state, obs, action)`. Workers whose episode has
ended stay in the batch with weight 0; nothing branches on them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from ldn_jax.learners.base import LearnerState, Segment

Array = jax.Array

WorldStep = Callable[[Array, Any, Array, Array], tuple[Array, Any, Array, Array, Array, dict]]
"""`(key, world_state, obs [W, d], action [W] or [W, a]) -> (next_obs, world_state,
reward [W], terminated [W], truncated [W], extras {name: [W]})`. The action is the one the
env executes (continuous actions clipped to the bounds); segments keep the policy's sample."""


@struct.dataclass
class EpisodeCarry:
    learner: LearnerState
    obs: Array
    """`[W, obs_size]`; frozen at the last observation once a worker's episode ends."""
    world: Any
    alive: Array
    """`[W]` bool: the worker's episode is still running."""
    time: Array
    """Steps taken, int32."""


@struct.dataclass
class Episodes:
    """What one batch of W episodes produced."""

    steps: Segment
    """Every step, `[T', W, ...]` with T' = max_steps rounded up to whole segments."""
    extras: dict
    """World extras per step, `[T', W]`."""
    losses: dict
    """Learner losses averaged over segments that had live steps."""

    @property
    def returns(self) -> Array:
        return jnp.sum(self.steps.reward * self.steps.weight, axis=0)

    @property
    def lengths(self) -> Array:
        return jnp.sum(self.steps.weight, axis=0).astype(jnp.int32)


def play_episodes(
    key: Array,
    learner_state: LearnerState,
    learner: Any,
    world_step: WorldStep,
    obs: Array,
    world: Any,
    max_steps: int,
) -> tuple[LearnerState, Episodes]:
    """Play one episode on each of W workers, updating the learner every `n_steps` steps.

    An episode ends on `terminated`, on `truncated`, or after `max_steps` steps.
    """
    n_steps = learner.config.n_steps
    n_segments = math.ceil(max_steps / n_steps)
    workers = obs.shape[0]

    def step(carry: EpisodeCarry, key: Array):
        k_act, k_world = jax.random.split(key)
        action = learner.act(carry.learner.params, k_act, carry.obs)
        next_obs, world, reward, terminated, truncated, extras = world_step(
            k_world, carry.world, carry.obs, learner.env_action(action)
        )
        truncated = (truncated | (carry.time + 1 >= max_steps)) & ~terminated
        done = terminated | truncated
        transition = Segment(
            obs=carry.obs,
            action=action,
            reward=reward,
            next_obs=next_obs,
            terminated=terminated,
            done=done,
            weight=carry.alive.astype(jnp.float32),
        )
        alive = carry.alive & ~done
        keep = lambda new, old: jnp.where(alive.reshape((-1,) + (1,) * (new.ndim - 1)), new, old)
        carry = carry.replace(
            obs=keep(next_obs, carry.obs),
            world=jax.tree.map(keep, world, carry.world),
            alive=alive,
            time=carry.time + 1,
        )
        return carry, (transition, extras)

    def segment(carry: EpisodeCarry, key: Array):
        k_steps, k_update = jax.random.split(key)
        carry, (transitions, extras) = jax.lax.scan(step, carry, jax.random.split(k_steps, n_steps))
        learner_state, losses = learner.update(carry.learner, transitions, k_update)
        return carry.replace(learner=learner_state), (transitions, extras, losses)

    carry = EpisodeCarry(
        learner=learner_state,
        obs=obs,
        world=world,
        alive=jnp.ones((workers,), bool),
        time=jnp.zeros((), jnp.int32),
    )
    keys = jax.random.split(key, n_segments)
    # The loop over segments stops once every worker's episode has ended. The mask alone
    # defines the result: a segment with no live step changes nothing (`keep_if_any`), so
    # skipping it is pure savings. Under vmap the loop runs until the whole batch is done.
    out_shape = jax.eval_shape(segment, carry, keys[0])[1]
    outputs = jax.tree.map(lambda x: jnp.zeros((n_segments, *x.shape), x.dtype), out_shape)

    def cond(loop):
        index, carry, _ = loop
        return (index < n_segments) & carry.alive.any()

    def body(loop):
        index, carry, outputs = loop
        carry, out = segment(carry, keys[index])
        outputs = jax.tree.map(
            lambda buf, x: jax.lax.dynamic_update_index_in_dim(buf, x, index, 0), outputs, out
        )
        return index + 1, carry, outputs

    _, carry, (steps, extras, losses) = jax.lax.while_loop(cond, body, (0, carry, outputs))
    live = (steps.weight.sum(axis=(1, 2)) > 0).astype(jnp.float32)
    flat = lambda x: x.reshape((n_segments * n_steps, *x.shape[2:]))
    losses = jax.tree.map(lambda x: (x * live).sum() / jnp.maximum(live.sum(), 1.0), losses)
    episodes = Episodes(
        steps=jax.tree.map(flat, steps), extras=jax.tree.map(flat, extras), losses=losses
    )
    return carry.learner, episodes
