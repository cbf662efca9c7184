"""The order the test files are handed to the xdist workers (`make test`: `--dist loadfile`),
the compiler's optimisations per test, and the guard that fails an `optimized` test run
without XLA's optimisations.

The files are handed out in collection order, so a heavy file collected late (test_paper.py's
smoke fixture trains 14 runs, about 3.5 minutes) would leave one worker running it while the
other idles. The heaviest files go first; the rest keep their order.

The whole session shares one persistent compilation cache (a temporary directory, set before
any test imports JAX and inherited by the xdist workers and the commands tests start), so a
program that several tests compile is compiled once: many tests train the same tiny configs.
A command given `--compile-cache DIR` uses its own directory as before.

Compiling dominates most tests (tiny budgets), so the session compiles without most of XLA's
optimisations (JAX_DISABLE_MOST_OPTIMIZATIONS, inherited as the cache is), except in a test
marked `optimized`: it compares the bits of two different programs, which the optimisations
decide, so it gets them back (in this process and in the commands it starts), as does a
module fixture whose run such a test holds to its bits (`optimised`). Measured 2026-12-07,
`make test` on an idle 2-core machine: 776 s, against 969 s with the optimisations on for
every test. A caller who sets the variable keeps it everywhere: `make test-slow` sets it to 0
(learning tests run long enough that the optimisations pay), and a caller who sets it to 1
has the guard below fail the `optimized` tests.

The same session also compiles with XLA's older CPU emitters (`--xla_cpu_use_fusion_emitters
=false` in XLA_FLAGS): a CartPole `ldn` chunk compiles in 2.0 s against 3.8 s, and the suite
took 678 s against 950 s (2026-12-08, docs/logs/benchmarks.md). The bits of a program can
differ between the two emitters, so an `optimized` test gets the default emitters back: in
the commands it starts through XLA_FLAGS, in this process through a compile option that
overrides the flag (XLA_FLAGS is read once, when the backend starts).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile

import pytest

FAST = "LDN_JAX_TESTS_UNOPTIMIZED"
"""Set by the session (not by a caller): the tests compile without most optimisations."""
CACHE_VARIABLES = {
    "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0",
    "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "-1",
}
OLD_EMITTERS = "--xla_cpu_use_fusion_emitters=false"
"""Compiles the tests' programs in about half the time (the module's docstring)."""


def _xla_flags(old_emitters: bool) -> None:
    flags = [f for f in os.environ.get("XLA_FLAGS", "").split() if f != OLD_EMITTERS]
    os.environ["XLA_FLAGS"] = " ".join([*flags, OLD_EMITTERS] if old_emitters else flags)


def pytest_configure(config):
    if hasattr(config, "workerinput") or "JAX_COMPILATION_CACHE_DIR" in os.environ:
        return  # an xdist worker (it inherits the controller's), or a cache set by the caller
    config._session_cache = tempfile.mkdtemp(prefix="ldn-jax-test-cache-")
    os.environ.update({"JAX_COMPILATION_CACHE_DIR": config._session_cache, **CACHE_VARIABLES})
    if "JAX_DISABLE_MOST_OPTIMIZATIONS" not in os.environ:
        config._session_xla_flags = os.environ.get("XLA_FLAGS")
        os.environ.update({"JAX_DISABLE_MOST_OPTIMIZATIONS": "1", FAST: "1"})
        _xla_flags(old_emitters=True)


def pytest_unconfigure(config):
    path = getattr(config, "_session_cache", None)
    if path:
        shutil.rmtree(path, ignore_errors=True)
        names = ["JAX_COMPILATION_CACHE_DIR", *CACHE_VARIABLES]
        if os.environ.get(FAST):
            names += ["JAX_DISABLE_MOST_OPTIMIZATIONS", FAST, "XLA_FLAGS"]
        for name in names:
            os.environ.pop(name, None)
        if getattr(config, "_session_xla_flags", None) is not None:
            os.environ["XLA_FLAGS"] = config._session_xla_flags


HEAVY_FIRST = ("test_paper.py", "test_train.py", "test_branched.py")


def pytest_collection_modifyitems(session, config, items):
    def rank(item) -> int:
        name = item.path.name
        return HEAVY_FIRST.index(name) if name in HEAVY_FIRST else len(HEAVY_FIRST)

    items.sort(key=rank)  # stable: each file's tests keep their order


@contextlib.contextmanager
def optimised():
    """XLA's optimisations and default emitters on within the block (this process and the
    commands it starts), where the session turned them off; nothing otherwise. For a test
    marked `optimized` (below, automatically) and for a module fixture whose run such a test
    compares bits with."""
    if not os.environ.get(FAST) or os.environ["JAX_DISABLE_MOST_OPTIMIZATIONS"] == "0":
        yield  # a caller's setting, or already on (a nested use)
        return
    import jax
    from jax._src import compiler

    session_options = compiler.get_compile_options

    def default_emitters(*args, env_options_overrides=None, **kwargs):
        overrides = {"xla_cpu_use_fusion_emitters": True, **(env_options_overrides or {})}
        return session_options(*args, env_options_overrides=overrides, **kwargs)

    def switch(off: bool) -> None:
        # JAX's in-memory caches do not key on the setting: a function jitted under the
        # other one would run as it was compiled (the persistent cache does key on both)
        os.environ["JAX_DISABLE_MOST_OPTIMIZATIONS"] = "1" if off else "0"
        _xla_flags(old_emitters=off)
        compiler.get_compile_options = session_options if off else default_emitters
        jax.config.update("jax_disable_most_optimizations", off)
        jax.clear_caches()

    switch(False)
    try:
        yield
    finally:
        switch(True)


@pytest.fixture(autouse=True)
def _optimisations(request):
    if request.node.get_closest_marker("optimized"):
        with optimised():
            yield
    else:
        yield


def pytest_runtest_setup(item):
    """A test marked `optimized` compares the bits of two different programs, which XLA's
    optimisations decide: under JAX_DISABLE_MOST_OPTIMIZATIONS it would check another
    compiler's bits (a two-pass `make test`, the rest without optimisations, was tried and
    was slower: 15:17 against 12:41)."""
    value = os.environ.get("JAX_DISABLE_MOST_OPTIMIZATIONS", "0").lower()
    chosen = value in ("y", "yes", "t", "true", "on", "1") and not os.environ.get(FAST)
    if item.get_closest_marker("optimized") and chosen:
        pytest.fail("an `optimized` test needs XLA's optimisations: unset the variable")
