"""Save and restore the whole batched `TrainState` with orbax."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import orbax.checkpoint as ocp

from ldn_jax.trainer import TrainState


def _raw(state: TrainState) -> TrainState:
    # Typed PRNG keys are stored as their raw uint32 data.
    return state.replace(key=jax.random.key_data(state.key))


def _to_storable(state: TrainState) -> TrainState:
    # orbax refuses zero-size arrays (a MuJoCo env state carried by schedule "steps" has
    # some): each is stored as one zero and restored to its empty shape.
    return jax.tree.map(lambda x: jnp.zeros((1,), x.dtype) if x.size == 0 else x, _raw(state))


def save(path: Path, state: TrainState) -> None:
    """Write `state` to the directory `path` (orbax commits it atomically)."""
    checkpointer = ocp.StandardCheckpointer()
    checkpointer.save(Path(path).resolve(), _to_storable(state), force=True)
    checkpointer.wait_until_finished()


def restore(path: Path, like: TrainState) -> TrainState:
    """Restore into the structure, shapes and dtypes of `like` (which may be abstract).

    In one process the arrays come back on its first device, whatever devices saved them
    (a run trained with `--devices 2` loads for `ldn-jax eval`, or resumes, with one; the
    trainer then places them). Across processes, on the devices that saved them."""
    target = jax.eval_shape(_to_storable, like)
    if jax.process_count() == 1:
        device = jax.sharding.SingleDeviceSharding(jax.devices()[0])
        on_device = lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=device)
        target = jax.tree.map(on_device, target)
    state = _restore(Path(path).resolve(), target)
    empty = lambda x, shape: jnp.zeros(shape.shape, shape.dtype) if shape.size == 0 else x
    state = jax.tree.map(empty, state, jax.eval_shape(_raw, like))
    return state.replace(key=jax.random.wrap_key_data(state.key))


def _restore(path: Path, target: TrainState) -> TrainState:
    """orbax's restore into `target`; a checkpoint written before a field that is None in
    `target` existed (the state keeps its layout where a setting is off: the learned
    termination's `ModelState.termination` and `Transitions.terminated`) lacks that field's
    key, so it is restored without it: every array of `target` must still be on disk."""
    try:
        return ocp.StandardCheckpointer().restore(path, target)
    except ValueError as error:
        if "structures do not match" not in str(error):
            raise
        restore_args = ocp.checkpoint_utils.construct_restore_args(target)
        args = ocp.args.PyTreeRestore(target, restore_args, partial_restore=True)
        try:
            state = ocp.PyTreeCheckpointer().restore(path, args=args)
        except Exception:  # orbax says so in several ways: the first error says it best
            raise error from None
        if any(isinstance(x, jax.ShapeDtypeStruct) for x in jax.tree.leaves(state)):
            raise error from None
        return state
