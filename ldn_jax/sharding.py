"""Seeds across devices and hosts: the `[K, S]` batch split along S with `jax.sharding`.

Every `[K, S, ...]` leaf of the training state and of the metrics is cut along the seeds axis
into equal blocks, one per device of a 1-D mesh (`NamedSharding(mesh, P(None, "seeds"))`);
what the whole batch shares (the K values, an evaluation key) is replicated. Each device runs
the same vmapped program on its `[K, S / devices]` block (`jax.shard_map`), so devices never
talk to each other inside a chunk. Multi-host: after `jax.distributed.initialize` the mesh
spans the devices of every process, and each process computes and holds its own seeds.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental import multihost_utils
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

SEEDS_AXIS = "seeds"

SHARDED_COMPILER_OPTIONS = {"xla_disable_hlo_passes": "spmd-cleanup"}
"""XLA options for every program compiled with a mesh, so that it computes what the
one-device program computes. XLA's SPMD partitioner ends with a cleanup pipeline (DCE, tuple
simplification, CSE) that a one-device compile does not run; its CSE merges broadcasts before
the first algebraic simplification, which then rewrites fewer `x / broadcast(c)` as
`x * broadcast(1 / c)` (optax Adam's bias correction, means), and losses drift in the last
bits from the first iteration. The passes after it (DCE and CSE included) run in both."""

BITWISE_COMPILER_OPTIONS = {
    "xla_cpu_experimental_ynn_fusion_type": "LIBRARY_FUSION_TYPE_INDIVIDUAL_DOT"
}
"""XLA options of `bitwise` programs, one device or many: YNNPACK keeps its matmuls but no
longer fuses reductions (jaxlib 0.10.2's default is dots and reductions), whose rounding
depends on the `[K, S]` batch a device holds (with K > 1: 4 seeds on one device and 2 + 2 on
two differ from the first iteration)."""


def compiler_options(mesh: Mesh | None, bitwise: bool) -> dict | None:
    """The XLA options of a program over the seeds, on one device (no mesh) or a mesh."""
    options = {}
    if mesh is not None:
        options |= SHARDED_COMPILER_OPTIONS
    if bitwise:
        options |= BITWISE_COMPILER_OPTIONS
    return options or None


def seed_mesh(devices: int | None = None) -> Mesh:
    """A 1-D mesh over the first `devices` devices (None: every device of every process)."""
    available = jax.devices()
    count = len(available) if devices is None else devices
    if not 1 <= count <= len(available):
        raise ValueError(
            f"{count} devices asked for, {len(available)} {available[0].platform} device(s) "
            "available (on CPU, `jax.config.update('jax_num_cpu_devices', N)` before JAX "
            "starts makes N, as the training command's --devices N does)"
        )
    return Mesh(np.asarray(available[:count]), (SEEDS_AXIS,))


def check_divisible(seeds: int, mesh: Mesh) -> None:
    """Every device gets the same number of seeds: no padding, so no wasted or fake runs."""
    if seeds % mesh.size:
        raise ValueError(
            f"--seeds {seeds} cannot be split evenly over {mesh.size} devices; "
            f"choose a multiple of {mesh.size}"
        )


def batch_sharding(mesh: Mesh) -> NamedSharding:
    """Where a `[K, S, ...]` array lives: split along S, whole along K and the rest."""
    return NamedSharding(mesh, P(None, SEEDS_AXIS))


def shard_seeds(fn: Callable, mesh: Mesh, bitwise: bool = False) -> Callable:
    """`fn(batch, shared) -> out` run by each device on its block of seeds.

    `batch` and every leaf of `out` are `[K, S, ...]`; `shared` (K values, a key) is given
    whole to every device. The body has no collectives, so nothing crosses devices.
    With `bitwise`, a device whose block is a single seed computes it twice (see
    `_never_one_seed`), so that it runs the kernels of a batch of seeds.
    """
    return jax.shard_map(
        _never_one_seed(fn) if bitwise else fn,
        mesh=mesh,
        in_specs=(P(None, SEEDS_AXIS), P()),
        out_specs=P(None, SEEDS_AXIS),
        # Scan carries inside start from constants (the same on every device) and become
        # per-seed values; the varying-axis check would demand a pcast at each of them.
        check_vma=False,
    )


def _never_one_seed(fn: Callable) -> Callable:
    """`fn` on a block of seeds, a one-seed block run as two copies of itself.

    XLA drops size-1 dimensions, so a one-seed block compiles to other kernels than a batch
    of seeds (with K = 1: unbatched matrix-vector products, emitted as XLA's own GEMV loops
    rather than batched matmuls; with K > 1, other YNNPACK fusions), which round
    differently. Two identical copies keep the batched program; the second is dropped.
    """

    def body(batch, shared):
        if jax.tree.leaves(batch)[0].shape[1] > 1:
            return fn(batch, shared)
        twice = jax.tree.map(lambda x: jnp.concatenate([x, x], axis=1), batch)
        return jax.tree.map(lambda x: x[:, :1], fn(twice, shared))

    return body


def place(batch, mesh: Mesh):
    """Put a `[K, S, ...]` pytree on the mesh. Across hosts every process passes the same
    full value (the state is initialised the same everywhere) and keeps its own block."""
    return _put(batch, batch_sharding(mesh))


def replicate(value, mesh: Mesh):
    """Give every device of the mesh the whole of `value` (K values, a key)."""
    return _put(value, NamedSharding(mesh, P()))


def _put(tree, sharding: NamedSharding):
    # Built from host copies rather than `jax.device_put`, whose multi-host check that every
    # process passes the same value fails on NaN (the moving return starts as NaN). Arrays
    # that already span hosts (restored by orbax) are only resharded.
    def put(x):
        if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key):
            data = put(jax.random.key_data(x))
            return jax.random.wrap_key_data(data, impl=jax.random.key_impl(x))
        if isinstance(x, jax.Array) and not x.is_fully_addressable:  # already global
            return jax.device_put(x, sharding)
        host = np.asarray(x)
        return jax.make_array_from_callback(host.shape, sharding, lambda index: host[index])

    return jax.tree.map(put, tree)


def abstract(batch, mesh: Mesh | None):
    """Shapes and dtypes of a `[K, S, ...]` pytree, with the mesh's sharding when given:
    enough to lower and compile without computing the state."""
    sharding = None if mesh is None else batch_sharding(mesh)
    return jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=sharding), batch)


def to_host(tree):
    """NumPy copies of a pytree of arrays; across hosts each process gets the whole array."""
    leaves = jax.tree.leaves(tree)
    if all(getattr(x, "is_fully_addressable", True) for x in leaves):
        return jax.device_get(tree)
    return multihost_utils.process_allgather(tree, tiled=True)


def any_process(flag: bool) -> bool:
    """True on every process if `flag` is true on any (one process: `flag` itself)."""
    if jax.process_count() == 1:
        return flag
    return bool(np.any(multihost_utils.process_allgather(np.asarray(flag))))


def initialize_distributed(
    coordinator: str | None, num_processes: int | None, process_id: int | None
) -> None:
    """`jax.distributed.initialize`; what is None comes from JAX_COORDINATOR_ADDRESS or the
    cluster (SLURM, Open MPI, ...), as JAX detects it. Must run before any computation."""
    jax.distributed.initialize(
        coordinator_address=coordinator, num_processes=num_processes, process_id=process_id
    )
