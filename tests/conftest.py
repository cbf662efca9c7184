"""The order the test files are handed to the xdist workers (`make test`: `--dist loadfile`).

The files are handed out in collection order, so a heavy file collected late (test_paper.py's
smoke fixture trains 14 runs, about 3.5 minutes) would leave one worker running it while the
other idles. The heaviest files go first; the rest keep their order.
"""

from __future__ import annotations

HEAVY_FIRST = ("test_paper.py", "test_train.py", "test_branched.py")


def pytest_collection_modifyitems(session, config, items):
    def rank(item) -> int:
        name = item.path.name
        return HEAVY_FIRST.index(name) if name in HEAVY_FIRST else len(HEAVY_FIRST)

    items.sort(key=rank)  # stable: each file's tests keep their order
