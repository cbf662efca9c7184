"""Table 5: PPO2 vs PPO2-Model vs PPO2-LDN on InvertedPendulum, HalfCheetah and Hopper.

    python experiments/paper/table5.py [--scale cpu|paper] [--smoke] [--results DIR]

Pending: the learners do not support continuous actions yet, so every row is reported as
pending (with the trainer's reason) until they do; then the same code trains them and reports
the final moving return and, where the env has a threshold, episodes to it. The paper's
"episodes to reach the top" needs a definition of "the top" per task when these rows can run.
Writes table5.json into DIR/table5/.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from experiments.paper import common

ENVS = ("inverted_pendulum", "halfcheetah", "hopper")
ALGOS = ("ppo", "ppo-model", "ppo-ldn")


def rows(entries: list[dict]) -> list[dict]:
    out = []
    for entry in entries:
        env, algo = entry["env"], entry["algo"]
        paper = common.PAPER_TABLE5.get(env, (None, None, None))[ALGOS.index(algo)]
        row = {"env": env, "algo": algo, "status": entry["status"], "paper": paper}
        if entry["status"] == "done":
            runs = entry["summary"]["runs"]
            row["final_moving_return"] = common.describe([r["final_moving_return"] for r in runs])
            row["episodes_to_threshold"] = common.describe(
                [r["episodes_to_threshold"] for r in runs]
            )
        else:
            row["reason"] = entry["reason"]
        out.append(row)
    return out


def main(argv: list[str] | None = None) -> int:
    scale, results = common.parse_args(argv, __doc__)
    table = rows(common.collect_runs(ENVS, ALGOS, scale, results))
    out = common.out_dir(results, "table5")
    common.write_json(out / "table5.json", {**common.scale_record(scale), "rows": table})
    pending = sum(r["status"] == "pending" for r in table)
    print(f"wrote {out}/table5.json ({pending}/{len(table)} rows pending)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
