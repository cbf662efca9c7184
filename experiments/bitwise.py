"""Refactors that must not change what training computes: a fixed set of small CLI runs whose
metrics (wall times aside) are hashed, so that two commits can be compared to the bit.

    python -m experiments.bitwise OUT.json          # run them all, write the hashes
    python -m experiments.bitwise OUT.json --against BEFORE.json   # and compare

The runs cover each family and mode a refactor of the trainer touches: A2C, the LD draw at
two K, PPO with imagination, a sweep, the native MuJoCo engine, a grid of runs, and the
`branched` preset (halfcheetah's LD draw, hopper's critic-only rows, and the paper's
M1-vs-M0 LD on a probabilistic ensemble), and SAC alone and with MBPO's branches.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from ldn_jax.host.run_dir import RunDir

RUNS = {
    "a2c": "--env cartpole-v1 --algo a2c --episodes 40",
    "ldn-k": "--env cartpole-v1 --algo ldn --k 0.5,2 --episodes 40",
    "ppo-ldn": "--env cartpole-v1 --algo ppo-ldn --episodes 40",
    "sweep": "--env cartpole-v1 --algo ppo --episodes 40 --sweep agent.actor_lr=3e-4,1e-3",
    "native-pendulum-ppo": "--env inverted_pendulum --algo ppo --steps 4096 --backend native",
    "grid": "--env cartpole-v0,cartpole-v1 --algo a2c,ppo --episodes 16",
    "branched-halfcheetah": "--env halfcheetah --algo ppo-ldn --preset branched --steps 4096",
    "branched-hopper": "--env hopper --algo ppo-model --preset branched --steps 4096",
    "branched-m0": "--env hopper --algo ppo-ldn --preset branched --ld m0 --steps 4096",
    "sac": "--env hopper --algo sac --steps 1500 --set sac.learning_starts=500 "
    "--set sac.random_steps=0",
    "sac-model": "--env hopper --algo sac-model --preset branched --steps 1000",
}
"""Name -> the training command's flags (each run 2 seeds, quiet, into its own directory)."""


def digest(out: Path) -> str:
    """The hash of every metrics.jsonl under `out` (sorted by path), wall times left out."""
    h = hashlib.sha256()
    for path in sorted(out.rglob(RunDir(out).metrics_file.name)):
        h.update(str(path.relative_to(out)).encode())
        for line in path.read_text().splitlines():
            entry = json.loads(line)
            entry.pop("wall_seconds", None)
            h.update(json.dumps(entry, sort_keys=True).encode())
    return h.hexdigest()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path, help="where to write the hashes (JSON)")
    parser.add_argument("--against", type=Path, help="hashes of another commit to compare")
    parser.add_argument("--runs", default=",".join(RUNS))
    args = parser.parse_args(argv)
    hashes = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.runs.split(","):
            out = Path(tmp) / name
            flags = [*RUNS[name].split(), "--seeds", "2", "--quiet", "--out", str(out)]
            command = [sys.executable, "-m", "ldn_jax.host.cli", *flags]
            subprocess.run(command, check=True, capture_output=True)
            hashes[name] = digest(out)
            print(f"{name}: {hashes[name][:16]}", flush=True)
    args.out.write_text(json.dumps(hashes, indent=1) + "\n")
    if args.against is None:
        return 0
    before = json.loads(args.against.read_text())
    differ = [name for name in hashes if before.get(name) != hashes[name]]
    print("identical" if not differ else f"DIFFERENT: {', '.join(differ)}")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
