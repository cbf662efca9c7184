"""The run directory's exclusive lock: one training process per directory at a time.

A training process holds `LOCK_FILE` with `fcntl.flock` for its whole life, so a second
`--resume` (or `--out`) on the same directory is refused instead of interleaving metrics and
checkpoints. flock belongs to the open file: a killed process's lock dies with it, so nothing
stale is ever left to clear by hand.

(The rest of the run directory's format still lives in `experiments/run.py`; it moves here.)
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from collections.abc import Iterator
from pathlib import Path

LOCK_FILE = ".lock"
"""Inside the run directory; holds the pid of the process that holds the lock."""


class RunDirBusy(Exception):
    """Another process holds the run directory."""


@contextlib.contextmanager
def hold(run_dir: Path) -> Iterator[None]:
    """Hold `run_dir`'s lock until the block ends; raise `RunDirBusy` (one line) if another
    process (or another `hold` in this one) holds it. `run_dir` must exist."""
    fd = os.open(Path(run_dir) / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.read(fd, 32).decode(errors="replace").strip() or "unknown"
        os.close(fd)
        raise RunDirBusy(
            f"{run_dir} is in use by another training process (pid {holder}); wait for it to "
            "finish or stop it, then --resume"
        ) from None
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        yield
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)
