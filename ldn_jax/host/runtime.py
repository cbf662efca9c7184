"""Runtime setup: the persistent compile cache, multi-host start, the device mesh, and the
compiled training chunk (with `--dry-run`'s report of what it costs)."""

from __future__ import annotations

import argparse
import collections
import contextlib
import os
import time
from pathlib import Path

import jax

from ldn_jax import sharding
from ldn_jax.config import Config
from ldn_jax.host.settings import UsageError
from ldn_jax.trainer import Trainer


def host() -> dict:
    """What computed a run's bits besides its config: the CPU model and the versions of JAX
    and MuJoCo. XLA compiles for the CPU it runs on, so the same config and code on another
    CPU type (AVX-512 or not, Intel or AMD) may round differently from the first iteration."""
    import importlib.metadata

    import jaxlib

    cpu = "unknown"
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    try:
        mujoco = importlib.metadata.version("mujoco")
    except importlib.metadata.PackageNotFoundError:
        mujoco = None
    return {"cpu": cpu, "jax": jax.__version__, "jaxlib": jaxlib.__version__, "mujoco": mujoco}


def default_compile_cache() -> Path:
    """Per user: $XDG_CACHE_HOME/ldn-jax/jax-cache, else ~/.cache/ldn-jax/jax-cache."""
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "ldn-jax" / "jax-cache"


def enable_compile_cache(spec: str | None) -> Path | None:
    """Turn on JAX's persistent compilation cache in `spec` (None: the default directory;
    "none": off). A later process that compiles the same program loads it from there."""
    if spec == "none":
        return None
    path = Path(spec).expanduser() if spec else default_compile_cache()
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise UsageError(f"cannot use --compile-cache {path}: {error.strerror or error}") from None
    jax.config.update("jax_compilation_cache_dir", str(path))
    # The defaults skip programs that compile in under a second and small entries; on CPU
    # the many small programs (eager init ops) add up to seconds, so cache everything.
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
    return path


HOST_DEVICES_FLAG = "--xla_force_host_platform_device_count"


def make_host_devices(args: argparse.Namespace) -> None:
    """`--devices N` on one host: give JAX's CPU backend N devices, so that the seeds can be
    split over the cores (XLA runs each device's program on its own thread).

    JAX reads this once, when its backend starts, so it is set first thing; a count that
    XLA_FLAGS already gives, `--distributed` (one device per process's host) and a backend
    already started (the command called in-process) are left as they are. On GPU or TPU the
    mesh is made of the accelerators, and the extra CPU devices stay unused.
    """
    if args.distributed or not (args.devices or "").isdigit() or int(args.devices) < 2:
        return
    if HOST_DEVICES_FLAG in os.environ.get("XLA_FLAGS", ""):
        return
    # If the backend has started, this raises, and `device_mesh` says what is missing.
    with contextlib.suppress(RuntimeError):
        jax.config.update("jax_num_cpu_devices", int(args.devices))


def initialize_distributed(args: argparse.Namespace) -> None:
    try:
        sharding.initialize_distributed(args.coordinator, args.num_processes, args.process_id)
    except (RuntimeError, ValueError) as error:
        reason = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
        raise UsageError(f"--distributed: {reason}") from None


def device_mesh(args: argparse.Namespace, seeds: int):
    """The mesh that `--devices` asks for, or None for one device (no sharding)."""
    spec = args.devices or ("all" if args.distributed else "1")
    if spec == "all":
        count = None
    else:
        try:
            count = int(spec)
        except ValueError:
            raise UsageError(f"--devices must be a number or 'all', got {spec!r}") from None
        if count < 1:
            raise UsageError(f"--devices must be >= 1 or 'all', got {count}")
    if count == 1:
        return None
    try:
        mesh = sharding.seed_mesh(count)
        if args.distributed and mesh.size != jax.device_count():
            everyone = jax.device_count()
            raise ValueError(f"--distributed uses every device ({everyone}); drop --devices")
        sharding.check_divisible(seeds, mesh)
    except ValueError as error:
        raise UsageError(f"--devices {spec}: {error}") from None
    return mesh if mesh.size > 1 else None


KEPT_PROGRAMS = 4
"""Programs a process keeps (the newest): compiled chunks for `reuse` and `evaluator`'s jitted
functions share the slots, so two configs' worth."""

_programs: collections.OrderedDict = collections.OrderedDict()


def compile_chunk(
    trainer: Trainer, states, k, mesh=None, bitwise: bool = False, reuse: bool = False
) -> tuple[object, float, float]:
    """`(compiled chunk, lower seconds, compile seconds)`; `states` may be abstract.

    Without `reuse`, lowering (tracing) always runs and XLA's compile is what the persistent
    cache skips. With it, a chunk this process compiled for an equal config, mesh and state
    shapes is returned as it is, neither traced nor compiled, with 0 seconds (a resumed or
    repeated run in the same process: `train` called again, a notebook, the tests).
    """
    key = (trainer.config, mesh, bitwise, _optimisations())
    key += (_signature(states, mesh), _signature(k, mesh))
    if reuse and key in _programs:
        _programs.move_to_end(key)
        return _programs[key], 0.0, 0.0
    start = time.perf_counter()
    lowered = trainer.batched_chunk(mesh, bitwise).lower(states, k)
    lowered_at = time.perf_counter()
    compiled = lowered.compile()
    if reuse:
        _keep(key, compiled)
    return compiled, lowered_at - start, time.perf_counter() - lowered_at


def evaluator(trainer: Trainer, mesh=None, bitwise: bool = False):
    """`trainer.batched_evaluate(mesh, bitwise)`, the same jitted function (and so the same
    compiled programs) for an equal config within the process."""
    key = ("evaluate", trainer.config, mesh, bitwise, _optimisations())
    if key in _programs:
        _programs.move_to_end(key)
        return _programs[key]
    return _keep(key, trainer.batched_evaluate(mesh, bitwise))


def _optimisations() -> bool:
    """Whether XLA compiles with its optimisations now (`jax_disable_most_optimizations`
    unset): a program compiled under the other setting is another program."""
    return not jax.config.values.get("jax_disable_most_optimizations", False)


def _keep(key, program):
    _programs[key] = program
    while len(_programs) > KEPT_PROGRAMS:
        _programs.popitem(last=False)
    return program


def _signature(tree, mesh) -> tuple:
    """What a compiled program is specialised to: the tree's structure and each leaf's shape
    and dtype, and with a mesh its placement (without one, everything is on one device)."""
    leaves, structure = jax.tree.flatten(tree)
    place = (lambda x: getattr(x, "sharding", None)) if mesh is not None else (lambda x: None)
    return structure, tuple(
        (tuple(x.shape), str(x.dtype), getattr(x, "weak_type", False), place(x)) for x in leaves
    )


def dry_run(config: Config, mesh=None, cache: Path | None = None, bitwise: bool = False) -> dict:
    """Compile the chunk program without computing anything and print what it costs."""
    trainer = Trainer(config)
    states = sharding.abstract(jax.eval_shape(trainer.init_batch), mesh)
    k = trainer.point_values()
    k = k if mesh is None else sharding.replicate(k, mesh)
    compiled, lower_s, compile_s = compile_chunk(trainer, states, k, mesh, bitwise)
    cost = compiled.cost_analysis()
    cost = (cost[0] if isinstance(cost, list | tuple) else cost) or {}
    memory = compiled.memory_analysis()
    report = {
        "compile_seconds": round(lower_s + compile_s, 3),
        "lower_seconds": round(lower_s, 3),
        "xla_compile_seconds": round(compile_s, 3),
        "flops": float(cost.get("flops", float("nan"))),
        "bytes_accessed": float(cost.get("bytes accessed", float("nan"))),
        "argument_bytes": memory.argument_size_in_bytes,
        "output_bytes": memory.output_size_in_bytes,
        "alias_bytes": memory.alias_size_in_bytes,
        "temp_bytes": memory.temp_size_in_bytes,
    }
    devices = 1 if mesh is None else mesh.size
    batch = f"{config.seeds} seeds" + (f" x {len(config.k)} K" if config.uses_k else "")
    batch += "".join(f" x {len(values)} {name}" for name, values in config.sweep)
    mb = lambda n: f"{n / 2**20:,.1f} MB"
    print(
        f"dry run: {config.env} {config.algo}, {batch} on {devices} device(s), "
        f"{config.chunk_iterations} iterations per chunk; nothing written\n"
        f"compile: {report['compile_seconds']:.2f} s (trace and lower {lower_s:.2f} s, XLA "
        f"{compile_s:.2f} s; cache: {cache or 'off'})\n"
        f"cost per chunk, XLA's static count (each loop body once, whatever its trip count): "
        f"{report['flops']:.3g} FLOPs, {report['bytes_accessed']:.3g} bytes accessed\n"
        f"memory per device: arguments {mb(report['argument_bytes'])} (donated: aliased "
        f"{mb(report['alias_bytes'])}), outputs {mb(report['output_bytes'])}, temporaries "
        f"{mb(report['temp_bytes'])}"
    )
    return report
