"""The run directory: the one place that knows its files, their format and its lock.

    DIR/config.json          the run's `Config`, with the format version `run_format`
    DIR/metrics.jsonl        one JSON line per iteration, seed and K, appended as training goes
    DIR/summary.json         written once training and the final evaluation are done
    DIR/curves.png           moving return against episodes
    DIR/eval.json            `ldn-jax eval`'s gymnasium evaluations, one entry per seed and K
    DIR/tensorboard/         with `--logger tensorboard`
    DIR/wandb/               with `--logger wandb` (its run id in wandb/run-id, for resume)
    DIR/checkpoints/NAME/    the batched `TrainState` (orbax), NAME = chunk_00020 ... or final
    DIR/checkpoints/NAME.host.npz   beside it: history, session timings, the manifest
    DIR/.lock                held (flock) by the training process that writes here

Training, evaluation, plots, policy loading, calibration, the paper scripts and the bench
all go through `RunDir`. Its errors are `RunDirError`: one line, fit for a user.

A checkpoint counts once its host file exists (written last, atomically); its manifest holds
the SHA-256 of every file orbax wrote, so a damaged checkpoint is found before orbax reads it
and resume falls back to the newest one that is whole.

The lock: a training process holds `.lock` with `fcntl.flock` for its whole life, so a second
`--resume` (or `--out`) on the directory is refused instead of interleaving metrics and
checkpoints. flock belongs to the open file: a killed process's lock dies with it.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import io
import json
import os
import shutil
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ldn_jax.config import Config, validate
from ldn_jax.host import checkpoint

RUN_FORMAT = 1
"""Version of the layout (config.json, checkpoints); resume refuses others."""

FINAL = "final"
"""The checkpoint written when training ends (always kept)."""

KEEP_CHECKPOINTS = 2
"""Chunk checkpoints kept on disk, the newest ones."""

LOCK_FILE = ".lock"
"""Holds the pid of the process that holds the lock."""


class RunDirError(ValueError):
    """A run directory that cannot be used as asked; the message is one line."""


class RunDirBusy(RunDirError):
    """Another process holds the run directory."""


class CheckpointWriteError(RunDirError):
    """A checkpoint (or metrics line) could not be written: the disk is full, or similar."""


@dataclass(frozen=True)
class Checkpoint:
    """What a checkpoint restores: the batched states, the history `{name: [K, S, N, ...]}`
    and the session record (chunks done, timings, resumes)."""

    name: str
    states: object
    history: dict[str, np.ndarray]
    session: dict


@dataclass(frozen=True)
class RunDir:
    """A run directory at `path` (which may not exist yet)."""

    path: Path

    def __post_init__(self):
        object.__setattr__(self, "path", Path(self.path))

    def __str__(self) -> str:
        return str(self.path)

    # -- files --------------------------------------------------------------------------------

    @property
    def config_file(self) -> Path:
        return self.path / "config.json"

    @property
    def metrics_file(self) -> Path:
        return self.path / "metrics.jsonl"

    @property
    def summary_file(self) -> Path:
        return self.path / "summary.json"

    @property
    def curves_file(self) -> Path:
        return self.path / "curves.png"

    @property
    def eval_file(self) -> Path:
        return self.path / "eval.json"

    @property
    def tensorboard_dir(self) -> Path:
        return self.path / "tensorboard"

    @property
    def wandb_dir(self) -> Path:
        return self.path / "wandb"

    @property
    def checkpoints(self) -> Path:
        return self.path / "checkpoints"

    def holds_run(self) -> bool:
        return self.config_file.exists()

    def is_finished(self) -> bool:
        """Training ended: the final checkpoint and the summary are there."""
        return self.summary_file.is_file() and self._complete(FINAL)

    # -- config -------------------------------------------------------------------------------

    def write_config(self, config: Config) -> None:
        write_json(self.config_file, {"run_format": RUN_FORMAT, **config.to_dict()})

    def read_config(self) -> Config:
        """The run's config, validated; `RunDirError` if there is none or it is unusable."""
        if not self.config_file.is_file():
            raise RunDirError(f"{self} holds no run (no config.json)")
        try:
            data = json.loads(self.config_file.read_text())
        except (OSError, json.JSONDecodeError, UnicodeDecodeError) as error:
            raise RunDirError(f"{self.config_file} is corrupt: {error}") from None
        if not self.same_format(data):
            found = data.get("run_format") if isinstance(data, dict) else None
            raise RunDirError(
                f"{self} was written by another ldn-jax version (run format {found}, "
                f"this version reads {RUN_FORMAT})"
            )
        try:
            return validate(Config.from_dict(data))
        except (TypeError, ValueError) as error:
            raise RunDirError(
                f"{self.config_file} does not describe a valid run: {error}"
            ) from None

    @staticmethod
    def same_format(data) -> bool:
        """Whether a config.json's contents were written in this version's format."""
        return isinstance(data, dict) and data.get("run_format") == RUN_FORMAT

    # -- metrics, summary, evaluations -------------------------------------------------------

    @contextlib.contextmanager
    def metrics_writer(self, enabled: bool = True) -> Iterator[MetricsWriter]:
        """Appends lines to metrics.jsonl (to nothing when not `enabled`: a process that
        computes seeds but does not write)."""
        with open(self.metrics_file if enabled else os.devnull, "a") as f:
            yield MetricsWriter(f, self.metrics_file)

    def truncate_metrics(self, iterations: int) -> None:
        """Keep the lines up to `iterations` (and no half-written line); atomic."""
        if not self.metrics_file.exists():
            return
        kept = []
        for line in self.metrics_file.read_text().splitlines():
            try:
                if json.loads(line)["iteration"] <= iterations:
                    kept.append(line)
            except (json.JSONDecodeError, KeyError, TypeError):
                continue
        write_atomic(self.metrics_file, "".join(f"{line}\n" for line in kept).encode())

    def read_metrics(self) -> list[dict]:
        """metrics.jsonl's lines; an iteration logged twice (seed and K alike) counts once,
        its last line winning. A half-written last line is skipped."""
        lines: dict[tuple, dict] = {}
        with open(self.metrics_file) as f:
            for text in f:
                try:
                    line = json.loads(text)
                except json.JSONDecodeError:
                    continue
                lines[(line["k"], line["seed"], line["iteration"])] = line
        return list(lines.values())

    def write_summary(self, summary: dict) -> None:
        write_json(self.summary_file, summary)

    def read_summary(self) -> dict:
        return json.loads(self.summary_file.read_text())

    def record_eval(self, header: dict, result: dict) -> None:
        """Add `result` to eval.json, replacing an earlier evaluation of the same seed, K and
        sweep point."""
        try:
            runs = [
                r for r in json.loads(self.eval_file.read_text())["runs"] if isinstance(r, dict)
            ]
        except (OSError, ValueError, KeyError, TypeError):
            runs = []  # none yet, or unreadable: start afresh
        key = lambda r: (r.get("seed"), r.get("k"), r.get("sweep"))
        runs = [r for r in runs if key(r) != key(result)]
        write_json(self.eval_file, {**header, "runs": [*runs, result]})

    # -- checkpoints --------------------------------------------------------------------------

    def checkpoint_paths(self, name: str) -> tuple[Path, Path]:
        """The orbax directory of a checkpoint and the host file beside it."""
        return self.checkpoints / name, self.checkpoints / f"{name}.host.npz"

    def save_checkpoint(
        self, name: str, states, history: dict, session: dict, writer: bool = True
    ) -> None:
        """The training state (orbax, atomic), then the host file (atomic), then prune to
        the newest `KEEP_CHECKPOINTS` chunk checkpoints. `history` holds lists of chunks.

        Across hosts every process saves its seeds with orbax; the `writer` (process 0)
        writes the rest. An `OSError` (disk full ...) becomes a one-line
        `CheckpointWriteError`; the checkpoints written before are untouched."""
        state_dir, host_file = self.checkpoint_paths(name)
        try:
            checkpoint.save(state_dir, states)
            if not writer:
                return
            arrays = {f"history/{n}": np.concatenate(v, axis=2) for n, v in history.items() if v}
            buffer = io.BytesIO()
            np.savez(
                buffer,
                session=np.asarray(json.dumps(session)),
                manifest=np.asarray(json.dumps(_manifest(state_dir))),
                **arrays,
            )
            write_atomic(host_file, buffer.getvalue())
        except OSError as error:
            raise CheckpointWriteError(
                f"cannot write checkpoint {state_dir}: {error.strerror or error}"
            ) from None
        for old in self._chunk_names()[:-KEEP_CHECKPOINTS]:
            old_dir, old_host = self.checkpoint_paths(old)
            old_host.unlink(missing_ok=True)
            shutil.rmtree(old_dir, ignore_errors=True)

    def remove_partial_checkpoints(self) -> None:
        """Delete what a killed save left: orbax's temporary directories, our `.tmp` files."""
        for partial in self.checkpoints.glob("*tmp*"):
            if partial.is_dir():
                shutil.rmtree(partial, ignore_errors=True)
            else:
                partial.unlink(missing_ok=True)

    def checkpoint_names(self) -> list[str]:
        """Complete checkpoints (host file written), newest first: `final`, then chunks."""
        return [n for n in [FINAL, *reversed(self._chunk_names())] if self._complete(n)]

    def load_checkpoint(self, name: str, like) -> Checkpoint:
        """One checkpoint into the structure of `like` (may be abstract), its files checked
        against the manifest; `RunDirError` naming the damage otherwise."""
        state_dir, host_file = self.checkpoint_paths(name)
        try:
            with np.load(host_file) as host:
                session = json.loads(str(host["session"]))
                manifest = json.loads(str(host["manifest"]))
                history = {
                    n.split("/", 1)[1]: host[n] for n in host.files if n.startswith("history/")
                }
            found = _manifest(state_dir)
            damaged = sorted(f for f in manifest if found.get(f) != manifest[f])
            if damaged:
                raise ValueError(f"{damaged[0]} is missing or differs from what was written")
            states = checkpoint.restore(state_dir, like)
        except Exception as error:  # orbax, numpy and zipfile raise many kinds for a bad file
            reason = str(error).splitlines()[0][:160] if str(error) else type(error).__name__
            raise RunDirError(f"checkpoint {state_dir} is unreadable ({reason})") from None
        return Checkpoint(name, states, history, session)

    def load_latest(self, like) -> tuple[Checkpoint | None, list[str]]:
        """The newest checkpoint that loads whole, and a one-line reason for each newer one
        that did not; `(None, [])` when there is none. `RunDirError` when every one is
        damaged (resuming from scratch would silently throw the run away)."""
        skipped = []
        for name in self.checkpoint_names():
            try:
                return self.load_checkpoint(name, like), skipped
            except RunDirError as error:
                skipped.append(str(error))
        if skipped:
            raise RunDirError(
                f"{skipped[0]}; no earlier checkpoint is whole: delete {self.checkpoints} to "
                "train from scratch"
            )
        return None, []

    def has_final_checkpoint(self) -> bool:
        return (self.checkpoints / FINAL).is_dir()

    def restore_final(self, like):
        """The batched final states of a finished run (`like` gives the structure)."""
        if not self.has_final_checkpoint():
            raise RunDirError(f"{self} has no final checkpoint (training not finished?)")
        return checkpoint.restore(self.checkpoints / FINAL, like)

    def history(self) -> dict[str, np.ndarray]:
        """Per-iteration metrics of the whole run `{name: [K, S, N, ...]}` (final checkpoint)."""
        _, host_file = self.checkpoint_paths(FINAL)
        with np.load(host_file) as host:
            return {n.split("/", 1)[1]: host[n] for n in host.files if n.startswith("history/")}

    def _chunk_names(self) -> list[str]:
        return sorted(p.name for p in self.checkpoints.glob("chunk_?????") if p.is_dir())

    def _complete(self, name: str) -> bool:
        state_dir, host_file = self.checkpoint_paths(name)
        return state_dir.is_dir() and host_file.is_file()

    # -- the lock -----------------------------------------------------------------------------

    @contextlib.contextmanager
    def hold(self) -> Iterator[None]:
        """Hold the directory's lock until the block ends; `RunDirBusy` (one line) if another
        process (or another `hold` in this one) holds it. The directory must exist."""
        fd = os.open(self.path / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 32).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise RunDirBusy(
                f"{self} is in use by another training process (pid {holder}); wait for it to "
                "finish or stop it, then --resume"
            ) from None
        try:
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
            yield
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)


def hold(path: Path):
    """`RunDir(path).hold()`."""
    return RunDir(path).hold()


def read_config(path: Path) -> Config:
    """`RunDir(path).read_config()`: the config of the run in `path`."""
    return RunDir(path).read_config()


class MetricsWriter:
    """Appends whole lines to metrics.jsonl and flushes them; a failed write (disk full)
    becomes a one-line `CheckpointWriteError`."""

    def __init__(self, file, path: Path):
        self._file, self._path = file, path

    def write(self, lines: list[str]) -> None:
        try:
            self._file.write("".join(f"{line}\n" for line in lines))
            self._file.flush()
        except OSError as error:
            raise CheckpointWriteError(
                f"cannot write {self._path}: {error.strerror or error}"
            ) from None


def write_json(path: Path, data: dict) -> None:
    """Write atomically: a reader sees the old file or the new one, never half of one."""
    write_atomic(path, (json.dumps(data, indent=2) + "\n").encode())


def write_atomic(path: Path, data: bytes) -> None:
    """Write to a temporary file, flush it to disk, then rename it over `path`."""
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError:
        tmp.unlink(missing_ok=True)
        raise


def _manifest(state_dir: Path) -> dict[str, str]:
    """SHA-256 of every file orbax wrote, so that resume can tell a damaged checkpoint
    before orbax reads it (orbax's own errors on a truncated file are not one line)."""
    return {
        str(path.relative_to(state_dir)): hashlib.sha256(path.read_bytes()).hexdigest()
        for path in sorted(state_dir.rglob("*"))
        if path.is_file()
    }
