"""Train the A2C or PPO family (plain, -model, -ldn) on one env, many seeds and K at once.

    python experiments/run.py --env cartpole-v2 --algo ldn --seeds 5 --k 0.5,1,2

Writes config.json, metrics.jsonl, summary.json, curves.png and checkpoints/ into --out.
`--devices N` splits the seeds over N devices, `--distributed` over several hosts;
`--dry-run` compiles the training program and prints its cost without training.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import hashlib
import io
import json
import os
import shutil
import signal
import sys
import time
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import envs
from experiments.loggers import LOGGERS, Logger, NullLogger, make_logger
from experiments.plots import learning_curves
from ldn_jax import checkpoint, run_dir, sharding
from ldn_jax.config import (
    ALGORITHMS,
    DEFAULT_CHUNK,
    DEFAULT_EPISODES,
    LD_ESTIMATORS,
    PRESETS,
    Config,
    from_preset,
    validate,
)
from ldn_jax.metrics import threshold_crossing
from ldn_jax.policy import FINAL_CHECKPOINT
from ldn_jax.train import Trainer, failure_names


class UsageError(Exception):
    """Bad input: reported as one line on stderr with exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, not usage + message
        raise UsageError(message)


DEFAULTS = {
    "env": "cartpole-v2",
    "algo": "ldn",
    "seeds": 5,
    "k": "0.5,1,2",
    "episodes": 1600,
    "preset": "paper",
}
"""Defaults of the config flags; they are None in the parsed args so `--resume` can tell
which flags were given."""


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = _Parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", help=f"one of: {', '.join(envs.names())} (default cartpole-v2)")
    p.add_argument("--algo", help=f"one of: {', '.join(ALGORITHMS)} (default ldn)")
    p.add_argument("--seeds", type=int, help="number of vmapped seeds 0..N-1 (default 5)")
    p.add_argument("--k", help="comma-separated learning-degree gains K (default 0.5,1,2)")
    p.add_argument(
        "--episodes",
        type=int,
        help="real episodes per seed and K (default 1600; inverted_pendulum 800, other MuJoCo "
        "tasks 16: CPU budgets, raise them on a GPU)",
    )
    p.add_argument(
        "--backend",
        help="MuJoCo physics: native (MuJoCo's C engine, fast on CPU), mjx (for GPU/TPU) or "
        "auto (default: native on CPU, mjx on GPU/TPU)",
    )
    p.add_argument("--workers", type=int, help="synchronous workers (default 8)")
    p.add_argument("--preset", help=f"one of: {', '.join(PRESETS)} (default paper)")
    p.add_argument("--threshold", type=float, help="moving-return threshold")
    p.add_argument("--chunk", type=int, help="iterations per compiled chunk (default 5)")
    p.add_argument(
        "--ld",
        choices=LD_ESTIMATORS,
        help="learning-degree estimator: m0 (M1 vs its initial copy M0, the paper) or ensemble "
        "(disagreement of --ensemble-size models relative to their fit error) (default m0)",
    )
    p.add_argument(
        "--ensemble-size", type=int, metavar="E", help="members with --ld ensemble (default 5)"
    )
    p.add_argument("--out", help="run directory (default runs/ENV-ALGO-TIME)")
    p.add_argument("--resume", metavar="DIR", help="continue the run in DIR from its checkpoint")
    p.add_argument(
        "--checkpoint-every", type=int, default=20, help="chunks between checkpoints (0: end only)"
    )
    p.add_argument("--quiet", action="store_true", help="no live progress display")
    p.add_argument("--logger", default="none", choices=LOGGERS, help="extra metric sink")
    p.add_argument(
        "--devices",
        help="devices to split the seeds over: N or 'all' (default 1; with --distributed, all)",
    )
    p.add_argument(
        "--bitwise",
        action="store_true",
        default=None,
        help="metrics identical to the bit (CPU) whatever --devices, for runs that all use "
        "--bitwise: no YNNPACK reduction fusions (about 8%% slower), and a device holding "
        "one seed computes it twice; a resumed run keeps what it was started with",
    )
    p.add_argument(
        "--distributed",
        action="store_true",
        help="multi-host: jax.distributed.initialize (coordinator from the flags below, "
        "JAX_COORDINATOR_ADDRESS, or the cluster: SLURM, Open MPI); process 0 writes the files",
    )
    p.add_argument("--coordinator", metavar="HOST:PORT", help="process 0's address")
    p.add_argument("--num-processes", type=int, help="processes in all (one per host)")
    p.add_argument("--process-id", type=int, help="this process's index, 0..num-processes-1")
    p.add_argument(
        "--compile-cache",
        metavar="DIR",
        help=f"persistent compilation cache, or 'none' (default {default_compile_cache()})",
    )
    p.add_argument(
        "--dry-run",
        action="store_true",
        help="compile the training chunk, print compile seconds, FLOPs and memory, write nothing",
    )
    args = p.parse_args(argv)
    if args.checkpoint_every < 0:
        raise UsageError("--checkpoint-every must be >= 0")
    cluster = [f for f in ("coordinator", "num_processes", "process_id") if getattr(args, f)]
    if cluster and not args.distributed:
        raise UsageError(f"{_flag(cluster[0])} needs --distributed")
    if args.distributed and not (args.out or args.resume or args.dry_run):
        raise UsageError("--distributed needs --out (every process must name the same run)")
    return args


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


def _initialize_distributed(args: argparse.Namespace) -> None:
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
    if count == 1:
        return None
    try:
        mesh = sharding.seed_mesh(count)
        if args.distributed and mesh.size != jax.device_count():
            everyone = jax.device_count()
            raise ValueError(f"--distributed uses every device ({everyone}); drop --devices")
        sharding.check_divisible(seeds, mesh)
    except ValueError as error:
        raise UsageError(str(error)) from None
    return mesh if mesh.size > 1 else None


CONFIG_FLAGS = {
    "env": "env",
    "algo": "algo",
    "seeds": "seeds",
    "k": "k",
    "episodes": "episodes",
    "workers": "workers",
    "preset": "preset",
    "threshold": "threshold",
    "chunk": "chunk_iterations",
    "backend": "backend",
    "ld": "model.ld",
    "ensemble_size": "model.ensemble",
}
"""CLI flag (its argparse name) -> the config field it sets (`model.X`: a `ModelConfig` field)."""


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def _field(config: Config, field: str):
    for part in field.split("."):
        config = getattr(config, part)
    return config


def build_config(args: argparse.Namespace) -> Config:
    given = lambda name: getattr(args, name) if getattr(args, name) is not None else DEFAULTS[name]
    algo = given("algo")
    overrides = {"env": given("env"), "algo": algo, "seeds": given("seeds")}
    overrides["episodes"] = (
        args.episodes
        if args.episodes is not None
        else DEFAULT_EPISODES.get(overrides["env"], DEFAULTS["episodes"])
    )
    k = _parse_k(given("k"))
    overrides["k"] = k if ALGORITHMS.get(algo, ALGORITHMS["ldn"]).ld_stop else k[:1] or k
    if overrides["env"] in DEFAULT_CHUNK:
        overrides["chunk_iterations"] = DEFAULT_CHUNK[overrides["env"]]
    for flag in ("workers", "threshold", "chunk", "backend", "ld", "ensemble_size"):
        if getattr(args, flag) is not None:
            field = CONFIG_FLAGS[flag]
            if field.startswith("model."):
                overrides.setdefault("model", {})[field.split(".", 1)[1]] = getattr(args, flag)
            else:
                overrides[field] = getattr(args, flag)
    if args.ensemble_size is not None and args.ld != "ensemble":
        raise UsageError("--ensemble-size needs --ld ensemble")
    try:
        config = validate(from_preset(given("preset"), **overrides))
    except ValueError as error:
        raise UsageError(str(error)) from None
    return resolve_physics(config)


def resolve_physics(config: Config) -> Config:
    """A MuJoCo run records the engine `auto` picked, and its model must load (one line
    otherwise); other envs keep the config as it is."""
    if config.env not in envs.mujoco.TASKS:
        return config
    backend = envs.mujoco.resolve_backend(config.backend)
    try:
        envs.mujoco.engine(config.env, backend)
    except envs.mujoco.ModelError as error:
        raise UsageError(f"--backend {backend}: {error}") from None
    return dataclasses.replace(config, backend=backend)


def _parse_k(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise UsageError(f"--k must be comma-separated numbers, got {text!r}") from None


def read_run_config(run_dir: Path) -> Config:
    """The config of an existing run directory, or a one-line `UsageError`."""
    path = run_dir / "config.json"
    if not path.is_file():
        raise UsageError(f"{run_dir} holds no run (no config.json)")
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise UsageError(f"{path} is corrupt: {error}") from None
    if not isinstance(data, dict) or data.get("run_format") != RUN_FORMAT:
        found = data.get("run_format") if isinstance(data, dict) else None
        raise UsageError(
            f"{run_dir} was written by another ldn-jax version (run format {found}, "
            f"this version reads {RUN_FORMAT})"
        )
    try:
        return validate(Config.from_dict(data))
    except (TypeError, ValueError) as error:
        raise UsageError(f"{path} does not describe a valid run: {error}") from None


def check_resume_flags(args: argparse.Namespace, config: Config) -> None:
    """Flags given with `--resume` must agree with the stored config."""
    for flag, field in CONFIG_FLAGS.items():
        value = getattr(args, flag)
        if value is None:
            continue
        stored = _field(config, field)
        if flag == "backend" and value == "auto" and config.env in envs.mujoco.TASKS:
            value = envs.mujoco.resolve_backend(value)
        if flag == "k":
            value = _parse_k(value)
            stored = tuple(stored)
            if not config.algorithm.ld_stop:
                value = value[:1]
        if value != stored:
            raise UsageError(
                f"{_flag(flag)} {getattr(args, flag)} does not match the run being resumed "
                f"({field} = {stored}); drop the flag to resume"
            )
    if args.out is not None and Path(args.out).resolve() != Path(args.resume).resolve():
        raise UsageError("--out and --resume name different directories; give --resume alone")


def prepare_out(
    args: argparse.Namespace, config: Config, held: contextlib.ExitStack | None = None
) -> Path:
    """Create the run directory for a new run; with `held`, take its lock into `held` before
    checking that no run is there (so two processes cannot both start one)."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = Path(args.out) if args.out else Path("runs") / f"{config.env}-{config.algo}-{stamp}"
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as error:
        raise UsageError(f"cannot write to --out {out}: {error.strerror or error}") from None
    if held is not None:
        _hold(held, out)
    if (out / "config.json").exists():
        raise UsageError(f"{out} already holds a run; choose another --out or --resume {out}")
    return out


def _hold(held: contextlib.ExitStack, out: Path) -> None:
    try:
        held.enter_context(run_dir.hold(out))
    except run_dir.RunDirBusy as error:
        raise UsageError(str(error)) from None


def write_json(path: Path, data: dict) -> None:
    """Write atomically: a reader sees the old file or the new one, never half of one."""
    write_atomic(path, (json.dumps(data, indent=2) + "\n").encode())


def write_atomic(path: Path, data: bytes) -> None:
    """Write to a temporary file, flush it to disk, then rename it over `path`."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


LOSS_SUFFIXES = ("_loss", "_entropy", "_approx_kl", "_clip_fraction")
"""Metrics written under "losses" in metrics.jsonl."""


def metric_lines(
    config: Config, metrics: dict, wall_seconds: float, first_iteration: int
) -> list[str]:
    """One JSON line per K, seed and iteration of a chunk's metrics `[K, S, N, ...]`.

    `iteration` counts the host's iterations from `first_iteration`, so a run frozen by the
    non-finite guard still numbers its lines like the others.
    """
    lines = []
    losses = [name for name in metrics if name.endswith(LOSS_SUFFIXES)]
    n_k, seeds, n_iter = metrics["iteration"].shape
    for ki in range(n_k):
        for seed in range(seeds):
            for i in range(n_iter):
                at = lambda name, index=(ki, seed, i): metrics[name][index]
                line = {
                    "iteration": first_iteration + i,
                    "seed": seed,
                    "k": config.k[ki],
                    "episodes": int(at("episodes")),
                    "env_steps": int(at("env_steps")),
                    "imagined_steps": int(at("imagined_steps")),
                    "episode_return": float(at("episode_return")),
                    "moving_return": float(at("moving_return")),
                    "ld_mean": _finite_or_none(at("ld_mean")) if "ld_mean" in metrics else None,
                    "losses": {name: _finite_or_none(at(name)) for name in losses},
                    "wall_seconds": round(wall_seconds, 3),
                }
                lines.append(json.dumps(line))
    return lines


def _finite_or_none(value) -> float | None:
    value = float(value)
    return value if np.isfinite(value) else None


class Progress:
    """Live display of episodes, moving return, LD and throughput (rich), or nothing."""

    def __init__(self, total: int, quiet: bool):
        self.quiet = quiet
        if quiet:
            return
        from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn
        from rich.progress import Progress as RichProgress

        self.bar = RichProgress(
            TextColumn("[bold]episodes"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TextColumn("{task.fields[status]}"),
        )
        self.task = self.bar.add_task("train", total=total, status="compiling...")
        self.bar.start()

    def update(self, episodes: int, status: str) -> None:
        if not self.quiet:
            self.bar.update(self.task, completed=episodes, status=status)

    def stop(self) -> None:
        if not self.quiet:
            self.bar.stop()


RUN_FORMAT = 1
"""Version of the run-directory layout (config.json, checkpoints); resume refuses others."""

KEEP_CHECKPOINTS = 2
"""Chunk checkpoints kept on disk (the newest ones); `final` is always kept."""


class Interrupted(Exception):
    """Training stopped on request after a checkpoint; `--resume` continues it."""

    def __init__(self, signum: int, chunks_done: int, chunks: int):
        super().__init__(f"stopped after chunk {chunks_done}/{chunks}")
        self.signum, self.chunks_done, self.chunks = signum, chunks_done, chunks


class Stop:
    """SIGINT/SIGTERM set a flag; the loop finishes its chunk, checkpoints and stops.

    A second signal acts at once (the default handler), for a user who cannot wait.
    """

    def __init__(self):
        self.signum: int | None = None

    def install(self) -> Stop:
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, self._handle)
        return self

    def _handle(self, signum, frame) -> None:
        self.signum = signum
        signal.signal(signum, signal.SIG_DFL)

    def requested(self, chunks_done: int) -> bool:
        return self.signum is not None


def checkpoint_paths(out: Path, name: str) -> tuple[Path, Path]:
    """The orbax directory of a checkpoint and the host file (history, timings) beside it."""
    return out / "checkpoints" / name, out / "checkpoints" / f"{name}.host.npz"


def save_checkpoint(out: Path, name: str, states, history: dict, session: dict) -> None:
    """The training state (orbax, atomic), then the host file (atomic): a checkpoint counts
    only once its host file exists, so a kill between the two loses nothing but time.

    Across hosts every process saves its seeds with orbax; process 0 writes the rest."""
    state_dir, host_file = checkpoint_paths(out, name)
    checkpoint.save(state_dir, states)
    if jax.process_index() != 0:
        return
    buffer = io.BytesIO()
    arrays = {f"history/{n}": np.concatenate(v, axis=2) for n, v in history.items() if v}
    manifest = json.dumps(_manifest(state_dir))
    np.savez(
        buffer, session=np.asarray(json.dumps(session)), manifest=np.asarray(manifest), **arrays
    )
    write_atomic(host_file, buffer.getvalue())
    chunk_names = sorted(p.name for p in (out / "checkpoints").glob("chunk_?????") if p.is_dir())
    for old in chunk_names[:-KEEP_CHECKPOINTS]:
        old_dir, old_host = checkpoint_paths(out, old)
        old_host.unlink(missing_ok=True)
        shutil.rmtree(old_dir, ignore_errors=True)


def _manifest(state_dir: Path) -> dict[str, str]:
    """SHA-256 of every file orbax wrote, so that resume can tell a damaged checkpoint
    before orbax reads it (orbax's own errors on a truncated file are not one line)."""
    return {
        str(path.relative_to(state_dir)): hashlib.sha256(path.read_bytes()).hexdigest()
        for path in sorted(state_dir.rglob("*"))
        if path.is_file()
    }


def latest_checkpoint(out: Path) -> str | None:
    """The newest complete checkpoint's name (`final` first), or None."""
    names = sorted(p.name for p in (out / "checkpoints").glob("chunk_?????") if p.is_dir())
    for name in [FINAL_CHECKPOINT, *reversed(names)]:
        state_dir, host_file = checkpoint_paths(out, name)
        if state_dir.is_dir() and host_file.is_file():
            return name
    return None


def load_checkpoint(out: Path, name: str, like) -> tuple[object, dict, dict]:
    """`(states, history, session)` of a checkpoint, or a one-line `UsageError`."""
    state_dir, host_file = checkpoint_paths(out, name)
    try:
        with np.load(host_file) as host:
            session = json.loads(str(host["session"]))
            manifest = json.loads(str(host["manifest"]))
            history = {
                n.split("/", 1)[1]: [host[n]] for n in host.files if n.startswith("history/")
            }
        found = _manifest(state_dir)
        damaged = sorted(f for f in manifest if found.get(f) != manifest[f])
        if damaged:
            raise ValueError(f"{damaged[0]} is missing or differs from what was written")
        states = checkpoint.restore(state_dir, like)
    except Exception as error:  # orbax, numpy and zipfile raise many kinds for a bad file
        reason = str(error).splitlines()[0][:160] if str(error) else type(error).__name__
        raise UsageError(
            f"checkpoint {state_dir} is unreadable ({reason}); delete it and its "
            f"{host_file.name} to resume from an earlier checkpoint"
        ) from None
    return states, history, session


def _remove_partial_checkpoints(out: Path) -> None:
    """Delete what a killed save left: orbax's temporary directories, our `.tmp` files."""
    for partial in (out / "checkpoints").glob("*tmp*"):
        if partial.is_dir():
            shutil.rmtree(partial, ignore_errors=True)
        else:
            partial.unlink(missing_ok=True)


def truncate_metrics(path: Path, iterations: int) -> None:
    """Keep the metrics lines up to `iterations` (and no half-written line); atomic."""
    if not path.exists():
        return
    kept = []
    for line in path.read_text().splitlines():
        try:
            if json.loads(line)["iteration"] <= iterations:
                kept.append(line)
        except (json.JSONDecodeError, KeyError, TypeError):
            continue
    write_atomic(path, "".join(f"{line}\n" for line in kept).encode())


def compile_chunk(
    trainer: Trainer, states, k, mesh=None, bitwise: bool = False
) -> tuple[object, float, float]:
    """`(compiled chunk, lower seconds, compile seconds)`; `states` may be abstract.

    Lowering (tracing) always runs; XLA's compile is what the persistent cache skips.
    """
    start = time.perf_counter()
    lowered = trainer.batched_chunk(mesh, bitwise).lower(states, k)
    lowered_at = time.perf_counter()
    compiled = lowered.compile()
    return compiled, lowered_at - start, time.perf_counter() - lowered_at


def dry_run(config: Config, mesh=None, cache: Path | None = None, bitwise: bool = False) -> dict:
    """Compile the chunk program without computing anything and print what it costs."""
    trainer = Trainer(config)
    states = sharding.abstract(jax.eval_shape(trainer.init_batch), mesh)
    k = trainer.k_values() if mesh is None else sharding.replicate(trainer.k_values(), mesh)
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
    mb = lambda n: f"{n / 2**20:,.1f} MB"
    print(
        f"dry run: {config.env} {config.algo}, {config.seeds} seeds x {len(config.k)} K on "
        f"{devices} device(s), {config.chunk_iterations} iterations per chunk; nothing written\n"
        f"compile: {report['compile_seconds']:.2f} s (trace and lower {lower_s:.2f} s, XLA "
        f"{compile_s:.2f} s; cache: {cache or 'off'})\n"
        f"cost per chunk, XLA's static count (each loop body once, whatever its trip count): "
        f"{report['flops']:.3g} FLOPs, {report['bytes_accessed']:.3g} bytes accessed\n"
        f"memory per device: arguments {mb(report['argument_bytes'])} (donated: aliased "
        f"{mb(report['alias_bytes'])}), outputs {mb(report['output_bytes'])}, temporaries "
        f"{mb(report['temp_bytes'])}"
    )
    return report


def train(
    config: Config,
    out: Path,
    checkpoint_every: int,
    quiet: bool,
    stop: Stop | None = None,
    resume: bool = False,
    logger: Logger | None = None,
    mesh=None,
    bitwise: bool | None = None,
) -> dict:
    """Train (or, with `resume`, continue) the run in `out`; returns the summary.

    With a mesh (`ldn_jax.sharding.seed_mesh`) the seeds are split over its devices; across
    hosts only process 0 writes files. `bitwise`: a device with a single seed computes it
    twice (`ldn_jax.sharding.shard_seeds`); None: as the run being resumed was (else False).
    Raises `Interrupted` after checkpointing when `stop` asks for it between chunks.
    """
    stop = stop or Stop()
    logger = logger or NullLogger()
    writer = jax.process_index() == 0
    trainer = Trainer(config)
    like = jax.eval_shape(trainer.init_batch)
    chunks = config.iterations // config.chunk_iterations
    history: dict[str, list[np.ndarray]] = {}
    session = {"chunks_done": 0, "chunk_ends": [], "compile_seconds": None, "resumes": 0}
    if resume and writer:
        _remove_partial_checkpoints(out)
    found = latest_checkpoint(out) if resume else None
    if found is not None:
        states, history, session = load_checkpoint(out, found, like)
        session["resumes"] += 1
    else:
        if writer:
            write_json(out / "config.json", {"run_format": RUN_FORMAT, **config.to_dict()})
        states = trainer.init_batch()
    if bitwise is None:
        bitwise = session.get("bitwise", False)
    session["bitwise"] = bitwise
    if writer:
        truncate_metrics(out / "metrics.jsonl", session["chunks_done"] * config.chunk_iterations)
    reported = _report_failures(config, history, set())
    k = trainer.k_values()
    if mesh is not None:
        states, k = sharding.place(states, mesh), sharding.replicate(k, mesh)

    if session["chunks_done"] < chunks:
        progress = Progress(config.iterations * config.workers, quiet or not writer)
        progress.update(
            session["chunks_done"] * config.chunk_iterations * config.workers, "compiling..."
        )
        chunk_fn, lower_s, compile_s = compile_chunk(trainer, states, k, mesh, bitwise)
        if session["compile_seconds"] is None:
            session["compile_seconds"] = lower_s + compile_s
        train_seconds = session["chunk_ends"][-1] if session["chunk_ends"] else 0.0
        # Processes other than 0 compute their seeds and write nothing.
        with open(out / "metrics.jsonl" if writer else os.devnull, "a") as log:
            for chunk in range(session["chunks_done"], chunks):
                t0 = time.perf_counter()
                states, metrics = chunk_fn(states, k)
                metrics = sharding.to_host(metrics)
                train_seconds += time.perf_counter() - t0
                session["chunk_ends"].append(train_seconds)
                session["chunks_done"] = chunk + 1
                for name, value in metrics.items():
                    history.setdefault(name, []).append(value)
                first = chunk * config.chunk_iterations + 1
                log.write("\n".join(metric_lines(config, metrics, train_seconds, first)) + "\n")
                log.flush()
                logger.log(config, metrics, train_seconds)
                reported = _report_failures(config, {"failure": [metrics["failure"]]}, reported)
                progress.update(
                    session["chunks_done"] * config.chunk_iterations * config.workers,
                    _status(metrics, train_seconds),
                )
                last = chunk + 1 == chunks
                due = checkpoint_every and (chunk + 1) % checkpoint_every == 0
                # Across hosts all stop together: the checkpoint is a collective save.
                stopping = not last and sharding.any_process(stop.requested(chunk + 1))
                if not last and (due or stopping):
                    save_checkpoint(out, f"chunk_{chunk + 1:05d}", states, history, session)
                if stopping:
                    progress.stop()
                    logger.close()
                    raise Interrupted(stop.signum or signal.SIGINT, chunk + 1, chunks)
        progress.stop()
        logger.close()
        save_checkpoint(out, FINAL_CHECKPOINT, states, history, session)

    eval_key = jax.random.key(config.seeds + 10_000)
    if mesh is not None:
        eval_key = sharding.replicate(eval_key, mesh)
    eval_returns = sharding.to_host(trainer.batched_evaluate(mesh, bitwise)(states, eval_key))
    history = {name: np.concatenate(parts, axis=2) for name, parts in history.items()}
    summary = summarize(config, history, eval_returns, states, session)
    summary["devices"] = 1 if mesh is None else mesh.size
    summary["bitwise"] = bitwise
    if writer:
        write_json(out / "summary.json", summary)
        plot(config, history, out / "curves.png")
    return summary


def _status(metrics: dict, train_seconds: float) -> str:
    steps = int(metrics["env_steps"].sum(axis=(0, 1))[-1])
    status = f"moving return {np.nanmean(metrics['moving_return'][..., -1]):7.1f}"
    if "ld_mean" in metrics:
        status += f"  LD {np.nanmean(metrics['ld_mean'][..., -1]):.3f}"
    return status + f"  {steps / max(train_seconds, 1e-9):,.0f} env steps/s"


def _report_failures(config: Config, history: dict, reported: set) -> set:
    """Print one stderr line per run that newly became non-finite; returns all reported."""
    if not history.get("failure"):
        return reported
    failure = history["failure"][-1][..., -1]
    for ki, seed in zip(*np.nonzero(failure), strict=True):
        if (ki, seed) not in reported:
            what = ", ".join(failure_names(int(failure[ki, seed])))
            print(
                f"warning: seed {seed} K={config.k[ki]:g}: non-finite {what}; this run is "
                "frozen at its last finite state, the others go on",
                file=sys.stderr,
            )
            reported = reported | {(ki, seed)}
    return reported


def summarize(config, history, eval_returns, states, session) -> dict:
    threshold = config.resolved_threshold
    chunk_ends = session["chunk_ends"]
    train_seconds = chunk_ends[-1]
    failure, failed_iteration = sharding.to_host((states.failure, states.failed_iteration))
    total_steps = int(history["env_steps"][..., -1].sum())
    runs = []
    per_chunk = config.chunk_iterations
    for ki, k in enumerate(config.k):
        for seed in range(config.seeds):
            crossing = None
            if threshold is not None:
                crossing = threshold_crossing(
                    history["moving_after"][ki, seed],
                    history["lengths"][ki, seed],
                    history["env_steps"][ki, seed],
                    threshold,
                )
            seconds = None
            if crossing is not None:
                # Wall time of the whole vmapped batch, pro rata within the crossing's chunk.
                chunk, within = divmod(crossing[2], per_chunk)
                begin = chunk_ends[chunk - 1] if chunk else 0.0
                seconds = begin + (chunk_ends[chunk] - begin) * (within + 1) / per_chunk
            runs.append(
                {
                    "seed": seed,
                    "k": k,
                    "episodes_to_threshold": crossing[0] if crossing else None,
                    "env_steps_to_threshold": crossing[1] if crossing else None,
                    "seconds_to_threshold": round(seconds, 3) if seconds else None,
                    "final_moving_return": _finite_or_none(history["moving_return"][ki, seed, -1]),
                    "eval_return": float(eval_returns[ki, seed]),
                    "diverged": None
                    if failure[ki, seed] == 0
                    else {
                        "iteration": int(failed_iteration[ki, seed]),
                        "quantities": failure_names(int(failure[ki, seed])),
                    },
                }
            )
    return {
        "env": config.env,
        "algo": config.algo,
        "backend": config.backend,
        "threshold": threshold,
        "compile_seconds": round(session["compile_seconds"], 3),
        "train_seconds": round(train_seconds, 3),
        "env_steps_per_second": round(total_steps / train_seconds, 1),
        "imagined_steps": int(history["imagined_steps"][..., -1].sum()),
        "resumes": session["resumes"],
        "runs": runs,
    }


def plot(config: Config, history: dict, path: Path) -> None:
    episodes = history["episodes"][0, 0]
    curves = {
        (f"{config.algo} K={k:g}" if len(config.k) > 1 else config.algo): (
            episodes,
            history["moving_return"][ki],
        )
        for ki, k in enumerate(config.k)
    }
    learning_curves(curves, path, f"{config.env}: {config.algo}", config.resolved_threshold)


def main(argv: list[str] | None = None) -> int:
    held = contextlib.ExitStack()  # the run directory's lock, for the life of the process
    try:
        args = parse_args(argv)
        if args.distributed:
            _initialize_distributed(args)
        writer = jax.process_index() == 0
        cache = enable_compile_cache(args.compile_cache)
        if args.resume:
            out = Path(args.resume)
            if writer and out.is_dir() and not args.dry_run:
                _hold(held, out)
            config = read_run_config(out)
            check_resume_flags(args, config)
        else:
            config = build_config(args)
        mesh = device_mesh(args, config.seeds)
        if args.dry_run:
            dry_run(config, mesh, cache, bool(args.bitwise))
            return 0
        if not args.resume:
            out = prepare_out(args, config, held) if writer else Path(args.out)
        try:
            logger = make_logger(args.logger, out) if writer else NullLogger()
        except ValueError as error:
            raise UsageError(str(error)) from None
        summary = train(
            config,
            out,
            args.checkpoint_every,
            args.quiet,
            Stop().install(),
            bool(args.resume),
            logger,
            mesh,
            args.bitwise,
        )
    except UsageError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except Interrupted as stopped:
        name = signal.Signals(stopped.signum).name
        print(
            f"{name}: stopped after chunk {stopped.chunks_done}/{stopped.chunks}, checkpoint "
            f"and metrics written. Resume with:\n  python experiments/run.py --resume {out}",
            file=sys.stderr,
        )
        return 128 + stopped.signum
    finally:
        held.close()
    if not writer:
        return 0
    reached = [r for r in summary["runs"] if r["episodes_to_threshold"] is not None]
    print(
        f"{config.env} {config.algo}: {len(reached)}/{len(summary['runs'])} runs reached "
        f"{summary['threshold']}; compile {summary['compile_seconds']:.1f}s, "
        f"train {summary['train_seconds']:.1f}s, "
        f"{summary['env_steps_per_second']:,.0f} env steps/s"
    )
    diverged = [r for r in summary["runs"] if r["diverged"]]
    if diverged:
        print(f"{len(diverged)} run(s) diverged and were frozen: see summary.json", file=sys.stderr)
    print(f"curves:  {out / 'curves.png'}\nsummary: {out / 'summary.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
