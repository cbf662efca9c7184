"""Every paper script in order, in one process (`make paper`), then REPORT.md.

    python -m experiments.paper.all [--scale cpu|cpu-full|paper] [--smoke] [--results DIR]

The same as running table2.py, table3.py, figure4.py, figure5.py, figure9.py, calibration.py,
stops.py, table4.py, table5.py, targets.py and report.py one after the other with the same
flags; one process compiles each training program once.
"""

from __future__ import annotations

import sys
import time

from experiments.paper import (
    calibration,
    common,
    figure4,
    figure5,
    figure9,
    report,
    stops,
    table2,
    table3,
    table4,
    table5,
    targets,
)

SCRIPTS = (
    table2,
    table3,
    figure4,
    figure5,
    figure9,
    calibration,
    stops,
    table4,
    table5,
    targets,
    report,
)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    common.parse_args(argv, __doc__)  # `--help` and bad flags answered here, before any script
    for script in SCRIPTS:
        name = script.__name__.rsplit(".", 1)[-1]
        start = time.perf_counter()
        print(f"== {name}", flush=True)
        status = script.main(argv)  # a busy run stops them all: `common.script` says which
        print(f"== {name}: {time.perf_counter() - start:.0f}s", flush=True)
        if status:
            return status
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
