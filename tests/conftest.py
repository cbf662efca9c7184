"""The order the test files are handed to the xdist workers (`make test`: `--dist loadfile`),
and the guard that fails an `optimized` test run without XLA's optimisations.

The files are handed out in collection order, so a heavy file collected late (test_paper.py's
smoke fixture trains 14 runs, about 3.5 minutes) would leave one worker running it while the
other idles. The heaviest files go first; the rest keep their order.

The whole session shares one persistent compilation cache (a temporary directory, set before
any test imports JAX and inherited by the xdist workers and the commands tests start), so a
program that several tests compile is compiled once: many tests train the same tiny configs.
A command given `--compile-cache DIR` uses its own directory as before.
"""

from __future__ import annotations

import os
import shutil
import tempfile

import pytest

CACHE_VARIABLES = {
    "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0",
    "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "-1",
}


def pytest_configure(config):
    if hasattr(config, "workerinput") or "JAX_COMPILATION_CACHE_DIR" in os.environ:
        return  # an xdist worker (it inherits the controller's), or a cache set by the caller
    config._session_cache = tempfile.mkdtemp(prefix="ldn-jax-test-cache-")
    os.environ.update({"JAX_COMPILATION_CACHE_DIR": config._session_cache, **CACHE_VARIABLES})


def pytest_unconfigure(config):
    path = getattr(config, "_session_cache", None)
    if path:
        shutil.rmtree(path, ignore_errors=True)
        for name in ("JAX_COMPILATION_CACHE_DIR", *CACHE_VARIABLES):
            os.environ.pop(name, None)


HEAVY_FIRST = ("test_paper.py", "test_train.py", "test_branched.py")


def pytest_collection_modifyitems(session, config, items):
    def rank(item) -> int:
        name = item.path.name
        return HEAVY_FIRST.index(name) if name in HEAVY_FIRST else len(HEAVY_FIRST)

    items.sort(key=rank)  # stable: each file's tests keep their order


def pytest_runtest_setup(item):
    """A test marked `optimized` compares the bits of two different programs, which XLA's
    optimisations decide: under JAX_DISABLE_MOST_OPTIMIZATIONS it would check another
    compiler's bits (a two-pass `make test`, the rest without optimisations, was tried and
    was slower: 15:17 against 12:41)."""
    if item.get_closest_marker("optimized") and os.environ.get("JAX_DISABLE_MOST_OPTIMIZATIONS"):
        pytest.fail("an `optimized` test needs XLA's optimisations: unset the variable")
