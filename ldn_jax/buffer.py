"""A fixed-capacity ring buffer of real transitions, on device."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

Array = jax.Array


@struct.dataclass
class Transitions:
    """Model training data: inputs (obs, action) and targets (next_obs, reward)."""

    obs: Array
    """`[..., obs_size]`"""
    action: Array
    """`[..., action_size]` (one-hot for discrete actions)"""
    next_obs: Array
    """`[..., obs_size]`"""
    reward: Array
    """`[...]`"""
    terminated: Array | None = None
    """`[...]`, 1.0 where the step ended its episode by the task's own test; kept only for a
    learned termination (`ImagineConfig.termination`), None otherwise (so other buffers keep
    their layout)."""


@struct.dataclass
class Buffer:
    data: Transitions
    """Each field `[capacity, ...]`."""
    size: Array
    """Transitions stored, int32, at most capacity."""
    cursor: Array
    """Where the next transition goes, int32."""

    @property
    def capacity(self) -> int:
        return self.data.reward.shape[0]


def buffer_init(capacity: int, obs_size: int, action_size: int, terminated: bool = False) -> Buffer:
    """An empty buffer; `terminated`: it keeps each row's termination too."""
    zeros = lambda *shape: jnp.zeros((capacity, *shape), jnp.float32)
    data = Transitions(zeros(obs_size), zeros(action_size), zeros(obs_size), zeros())
    if terminated:
        data = data.replace(terminated=zeros())
    return Buffer(data=data, size=jnp.zeros((), jnp.int32), cursor=jnp.zeros((), jnp.int32))


def buffer_add(buffer: Buffer, batch: Transitions, valid: Array) -> Buffer:
    """Append the valid transitions of a flat batch (fields `[N, ...]`, valid `[N]`).

    Valid rows are packed in order behind the cursor; invalid rows are scattered out of
    range and dropped, so a masked rollout costs no capacity.
    """
    valid = valid.astype(jnp.int32)
    offset = jnp.cumsum(valid) - valid
    slot = (buffer.cursor + offset) % buffer.capacity
    slot = jnp.where(valid > 0, slot, buffer.capacity)
    data = jax.tree.map(lambda d, b: d.at[slot].set(b, mode="drop"), buffer.data, batch)
    added = valid.sum()
    return Buffer(
        data=data,
        size=jnp.minimum(buffer.size + added, buffer.capacity),
        cursor=(buffer.cursor + added) % buffer.capacity,
    )


def buffer_sample(buffer: Buffer, key: Array, batch_size: int) -> Transitions:
    """Uniform draw with replacement from the stored transitions."""
    index = jax.random.randint(key, (batch_size,), 0, jnp.maximum(buffer.size, 1))
    return jax.tree.map(lambda d: d[index], buffer.data)


def buffer_sample_recent(buffer: Buffer, key: Array, batch_size: int, window: int) -> Transitions:
    """Uniform draw with replacement from the newest `window` stored transitions (all of them
    while fewer are stored): the ring holds them in the order they were added, the newest
    just behind the cursor."""
    count = jnp.maximum(jnp.minimum(buffer.size, window), 1)
    back = jax.random.randint(key, (batch_size,), 0, count)
    index = (buffer.cursor - 1 - back) % buffer.capacity
    return jax.tree.map(lambda d: d[index], buffer.data)


HOLDOUT_EVERY = 10
"""One slot in this many (slots 0, 10, 20, ...) is held out from a probabilistic model's fit,
to rank its members (`ModelConfig.elites`)."""


def buffer_sample_split(buffer: Buffer, key: Array, batch_size: int, held_out: bool) -> Transitions:
    """Uniform draw with replacement from the held-out slots (every `HOLDOUT_EVERY`th) or
    from the others."""
    size = buffer.size
    held = (size + HOLDOUT_EVERY - 1) // HOLDOUT_EVERY
    count = held if held_out else size - held
    j = jax.random.randint(key, (batch_size,), 0, jnp.maximum(count, 1))
    index = j * HOLDOUT_EVERY if held_out else j + j // (HOLDOUT_EVERY - 1) + 1
    index = jnp.minimum(index, jnp.maximum(size - 1, 0))
    return jax.tree.map(lambda d: d[index], buffer.data)
