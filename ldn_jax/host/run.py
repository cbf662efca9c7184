"""Train the A2C or PPO family (plain, -model, -ldn) on one env, many seeds and K at once.

    python experiments/run.py --env cartpole-v2 --algo ldn --seeds 5 --k 0.5,1,2

Writes config.json, metrics.jsonl, summary.json, curves.png and checkpoints/ into --out.
`--devices N` splits the seeds over N devices, `--distributed` over several hosts;
`--dry-run` compiles the training program and prints its cost without training.

This file is the command: flags and config (`ldn_jax.host.flags`, fields set by name in
`ldn_jax.host.settings`), runtime setup (`ldn_jax.host.runtime`), the host loop
(`ldn_jax.host.training`), what a run reports (`ldn_jax.host.summaries`) and the run
directory (`ldn_jax.host.run_dir`) each live in their own.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import time
from pathlib import Path

import jax

from ldn_jax.config import Config, advisories
from ldn_jax.host import flags, runtime, settings, summaries
from ldn_jax.host.loggers import NullLogger, make_logger
from ldn_jax.host.run_dir import CheckpointWriteError, RunDir, RunDirError
from ldn_jax.host.settings import UsageError
from ldn_jax.host.training import Interrupted, Stop, TrainOptions, train


def main(argv: list[str] | None = None) -> int:
    """The training command; returns the exit code (2: bad input, one line on stderr)."""
    try:
        args = flags.parse_args(argv)
        members = flags.grid(args)
        runtime.make_host_devices(args)
        if args.distributed:
            runtime.initialize_distributed(args)
        cache = runtime.enable_compile_cache(args.compile_cache)
        if members is None:
            return train_one(args, cache)
        members = grid_members(members, args)
    except (UsageError, RunDirError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    return train_grid(members, cache)


def train_one(args, cache, stop: Stop | None = None) -> int:
    """One run: `args` as parsed, for one env and algorithm; returns the exit code."""
    held = contextlib.ExitStack()  # the run directory's lock, for the life of the run
    run = None
    writer = jax.process_index() == 0
    try:
        if args.resume:
            run = RunDir(args.resume)
            if writer and run.path.is_dir() and not args.dry_run:
                held.enter_context(run.hold())
            config = run.read_config()
            flags.check_resume_flags(args, config)
        else:
            config = flags.build_config(args)
        if args.explain:
            print("\n".join(flags.explain_field(args, args.explain)))
            return 0
        if args.list_fields:
            sources = None if args.resume else flags.field_sources(args)
            print("\n".join(settings.list_fields(config, sources)))
            return 0
        mesh = runtime.device_mesh(args, config.seeds)
        if args.dry_run:
            runtime.dry_run(config, mesh, cache, bool(args.bitwise))
            return 0
        if not args.resume:
            run = new_run_dir(args.out, config, held) if writer else RunDir(args.out)
            for line in advisories(config) if writer else ():
                print(f"warning: {line}", file=sys.stderr)
        try:
            logger = (
                make_logger(args.logger, run.path, config, args.wandb_project)
                if writer
                else NullLogger()
            )
        except ValueError as error:
            raise UsageError(str(error)) from None
        options = TrainOptions(
            checkpoint_every=args.checkpoint_every,
            quiet=args.quiet,
            stop=stop or Stop().install(),
            resume=bool(args.resume),
            logger=logger,
            mesh=mesh,
            bitwise=args.bitwise,
        )
        summary = train(config, run.path, options)
    except CheckpointWriteError as error:
        print(
            f"error: {error}; the checkpoints before it are intact: free space, then "
            f"--resume {run}",
            file=sys.stderr,
        )
        return 1
    except (UsageError, RunDirError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except Interrupted as stopped:
        name = signal.Signals(stopped.signum).name
        print(
            f"{name}: stopped after chunk {stopped.progress}, checkpoint "
            f"and metrics written. Resume with:\n  python experiments/run.py --resume {run}",
            file=sys.stderr,
        )
        return 128 + stopped.signum
    finally:
        held.close()
    if writer:
        summaries.closing_lines(config, summary, run)
    return 0


def grid_members(members: list, args) -> list:
    """The runs of a grid (`--env A,B --algo X,Y`), each with its `--out`: DIR/ENV-ALGO under
    the grid's `--out` (default runs/grid-STAMP). The same command again goes on where it
    stopped: a member whose directory holds a finished run is kept, one that was interrupted
    resumes (its settings checked as `--resume` checks them), the rest start. Every member's
    config is built and checked before any trains, so a bad name costs nothing."""
    root = Path(args.out or Path("runs") / f"grid-{time.strftime('%Y%m%d-%H%M%S')}")
    placed = []
    for member in members:
        config = flags.build_config(member)
        member.out = str(root / f"{config.env}-{config.algo}")
        there = RunDir(member.out)
        if there.is_finished():
            as_resumed = argparse.Namespace(**{**vars(member), "resume": member.out})
            flags.check_resume_flags(as_resumed, there.read_config())
            print(f"kept: {there} (finished)")
            continue
        if there.holds_run():
            member.resume = member.out
            flags.check_resume_flags(member, there.read_config())
        placed.append(member)
    return placed


def train_grid(members: list, cache) -> int:
    """Train a grid's runs one after another in this process (imports, the backend and
    programs shared between runs are paid once); stops at the first that does not finish,
    saying what did not start."""
    stop = Stop().install()
    for i, member in enumerate(members):
        name = Path(member.out).name
        if not member.quiet:
            print(f"[{i + 1}/{len(members)}] {name}" + (" (resumed)" if member.resume else ""))
        code = train_one(member, cache, stop)
        if code != 0:
            rest = [Path(m.out).name for m in members[i + 1 :]]
            if rest:
                print(
                    f"not started: {', '.join(rest)}; the same command again goes on from here",
                    file=sys.stderr,
                )
            return code
    return 0


def new_run_dir(out: str | None, config: Config, held: contextlib.ExitStack) -> RunDir:
    """Create the run directory of a new run and take its lock into `held` before checking
    that no run is there (so two processes cannot both start one)."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    run = RunDir(out or Path("runs") / f"{config.env}-{config.algo}-{stamp}")
    try:
        run.path.mkdir(parents=True, exist_ok=True)
        probe = run.path / ".write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as error:
        raise UsageError(f"cannot write to --out {run}: {error.strerror or error}") from None
    held.enter_context(run.hold())
    if run.holds_run():
        raise UsageError(f"{run} already holds a run; choose another --out or --resume {run}")
    return run


if __name__ == "__main__":
    sys.exit(main())
