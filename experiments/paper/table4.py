"""Table 4: total moving reward on six MuJoCo tasks, A2C-Model vs MBRL-LDN.

    python experiments/paper/table4.py [--scale cpu|paper] [--smoke] [--results DIR]

Pending: the learners do not support continuous actions yet, so every row is reported as
pending (with the trainer's reason) until they do; then the same code trains them. "Total
moving reward" is read as the final moving return. Writes table4.json into DIR/table4/.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from experiments.paper import common

ENVS = ("ant", "halfcheetah", "hopper", "reacher", "walker2d", "inverted_pendulum")
ALGOS = ("a2c-model", "ldn")


def rows(entries: list[dict]) -> list[dict]:
    out = []
    for entry in entries:
        env, algo = entry["env"], entry["algo"]
        paper = common.PAPER_TABLE4.get(env, (None, None))[ALGOS.index(algo)]
        row = {"env": env, "algo": algo, "status": entry["status"], "paper": paper}
        if entry["status"] == "done":
            final = [r["final_moving_return"] for r in entry["summary"]["runs"]]
            row.update(common.describe(final))
        else:
            row["reason"] = entry["reason"]
        out.append(row)
    return out


def main(argv: list[str] | None = None) -> int:
    scale, results = common.parse_args(argv, __doc__)
    table = rows(common.collect_runs(ENVS, ALGOS, scale, results))
    out = common.out_dir(results, "table4")
    record = {**common.scale_record(scale), "metric": "final moving return", "rows": table}
    common.write_json(out / "table4.json", record)
    pending = sum(r["status"] == "pending" for r in table)
    print(f"wrote {out}/table4.json ({pending}/{len(table)} rows pending)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
