"""REPORT.md from the result files: every table beside the paper's numbers, what reproduced
and what did not, the machine and the commands.

    python -m experiments.paper.report [--scale cpu|cpu-full|paper] [--smoke] [--results DIR]

Reads DIR/<result>/*.json (a result not produced yet is reported as missing) and writes
DIR/REPORT.md. It trains nothing.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from experiments.paper import common, report_mujoco, report_paper, report_studies
from experiments.paper.report_format import TITLES, Bullets, Section, render_section

NAMES = (
    "table2",
    "table3",
    "figure5",
    "figure9",
    "calibration",
    "readings",
    "rules",
    "table4",
    "table5",
    "targets",
)


def load(results: Path) -> dict[str, dict | None]:
    out = {}
    for name in NAMES:
        path = results / name / f"{name}.json"
        out[name] = json.loads(path.read_text()) if path.exists() else None
    return out


def setup(data: dict, scale: common.Scale) -> Section:
    first = next((d for d in data.values() if d), None)
    machine = first["machine"] if first else common.machine()
    flag = "--smoke" if scale.name == "smoke" else f"--scale {scale.name}"
    run = "make paper" + ("" if scale.name == "cpu" else f" SCALE={scale.name}")
    if scale.name == "smoke":
        run = "python -m experiments.paper.all --smoke"
    budgets = {
        env: ", ".join(f"{n:,} {unit}" for unit, n in b.items())
        for env, b in scale.mujoco_budgets.items()
    }
    left_out = [env for env in common.MUJOCO if env not in budgets]
    mujoco = (
        f"{scale.mujoco_seeds} seeds per run (the native MuJoCo engine on CPU); budgets per "
        "seed "
        + ", ".join(f"{env} {b}" for env, b in budgets.items())
        + (f"; pending at this scale: {', '.join(left_out)}." if left_out else ".")
        if budgets
        else "not run at this scale."
    )
    scripts = ("table2", "table3", "figure4", "figure5", "figure9", "calibration")
    items = [
        f"Scale `{scale.name}`: {scale.seeds} seeds per run (vmapped: one compiled program per "
        f"run), a budget of {scale.episodes:,} real episodes per seed (summed over "
        f"{scale.workers} synchronous workers), the `paper` preset (docs/paper.md), K = 1 unless "
        "stated. Episodes to threshold count real episodes in completion order; a run that never "
        "reaches the threshold within the budget is left out of mean and s.d. and counted in "
        "*reached*.",
        "Statistics (Agarwal et al., NeurIPS 2021): *IQM* is the interquartile mean over seeds "
        "(the mean of the middle half), with a bootstrap 95% interval (2,000 resamples, "
        "percentile; `ldn_jax/host/stats.py`, scipy); *P(better)* is the probability that a "
        "seed of the first algorithm does better than a seed of the second (fewer episodes, or "
        "a higher return), with its bootstrap interval; 0.5 is a tie. The paper's own columns "
        "(mean ± s.d.) are kept beside them. `ldn-jax compare RUN_DIR ...` prints the same for "
        "any runs.",
        f"MuJoCo (Tables 4 and 5, Figure 9's MuJoCo panels): {mujoco}{mujoco_time(data)}",
        f"{cpus(data) or 'Machine: ' + machine['cpu'] + ','} {machine['cores']} cores, JAX backend "
        f"{machine['jax_backend']}; jax {machine['jax']}, jaxlib {machine['jaxlib']}, Python "
        f"{machine['python']}; results dated {dated(data) or machine['date']}. The CPU was "
        "shared with other jobs, so seconds are indicative.",
        f"Commands: `{run}` (that is, `python -m experiments.paper.all {flag}`), "
        "or one script at a time: "
        + ", ".join(f"`python -m experiments.paper.{n} {flag}`" for n in scripts)
        + ", then `table4`, `table5` and `report` the same way. `--scale paper` "
        "raises the budget to 4,000 episodes and the calibration samples; `--smoke` is the "
        "tests' tiny budget. Training runs are kept under `runs/<scale>/` (not in git) and "
        "reused when their config matches.",
    ]
    return Section("Setup", [Bullets(items)])


def dated(data: dict) -> str:
    """When each result file was made: "2026-12-01" or "2026-11-22 (table2, ...), 2026-12-01
    (table4, ...)"; "" without files."""
    by_date: dict[str, list[str]] = {}
    for name, d in data.items():
        if d and "machine" in d:
            by_date.setdefault(d["machine"]["date"], []).append(name)
    if len(by_date) < 2:
        return next(iter(by_date), "")
    return ", ".join(f"{date} ({', '.join(names)})" for date, names in sorted(by_date.items()))


def cpus(data: dict) -> str:
    """The setup's machine, up to its cores: "Machine: AMD EPYC,", or where result files were
    written on several CPUs, which wrote which; "" without files."""
    by_cpu: dict[str, list[str]] = {}
    for name, d in data.items():
        if d and "machine" in d:
            by_cpu.setdefault(d["machine"]["cpu"], []).append(name)
    if len(by_cpu) < 2:
        return f"Machine: {next(iter(by_cpu))}," if by_cpu else ""
    written = "; ".join(f"{cpu} ({', '.join(names)})" for cpu, names in by_cpu.items())
    return (
        "Machines (where each result file was written; a run cached or recorded by an earlier "
        f"session trained on that session's machine): {written}; each with"
    )


def mujoco_time(data: dict) -> str:
    """The sentence giving the MuJoCo runs' wall time in the result files (training and
    compile, summed over runs; each run's seeds and K are one vmapped program), or ""."""
    runs = [r for r in (data.get("table4") or {}).get("rows", []) if r["status"] == "done"]
    runs += [r for r in (data.get("table5") or {}).get("rows", []) if r["status"] == "done"]
    panels = [p for p in (data.get("figure9") or {}).get("panels", []) if p["env"] in common.MUJOCO]
    timed = [*runs, *(p for p in panels if "train_seconds" in p)]
    if not timed:
        return ""
    seconds = sum(r["train_seconds"] + r["compile_seconds"] for r in timed)
    return (
        f" Wall time of these {len(timed)} runs: {seconds / 60:.0f} minutes of training and "
        "compile in all (evaluation and the scripts' own work not counted)."
    )


SECTIONS = (
    ("table2", report_paper.table2_section),
    ("table3", report_paper.table3_section),
    ("figure4", None),  # a figure only: `figure4_section` looks for it
    ("figure5", report_paper.figure5_section),
    ("figure9", report_paper.figure9_section),
    ("calibration", report_studies.calibration_section),
    ("readings", report_studies.readings_section),
    ("rules", report_studies.rules_section),
    ("table4", report_mujoco.table4_section),
    ("table5", report_mujoco.table5_section),
    ("targets", report_mujoco.targets_section),
)
"""The report's sections in order: result name -> builder of its `Section` from the result."""


def sections(results: Path, data: dict) -> list[Section]:
    out = []
    for name, build in SECTIONS:
        if build is None:
            out.append(report_paper.figure4_section(results))
        elif data[name] is None:
            out.append(Section.missing(TITLES[name], f"{name}.py"))
        else:
            out.append(build(data[name]))
    return out


def render(results: Path, scale: common.Scale) -> str:
    """The report; `scale` is used only where no result file says which scale made it."""
    data = load(results)
    made = {d["scale"] for d in data.values() if d}
    if len(made) == 1:
        scale = common.SCALES[made.pop()]
    body = sections(results, data)
    summary = Section(
        "What reproduced and what did not",
        [Bullets([f for section in body for f in section.findings])],
    )
    lines = [
        "# Reproduction report: MBRL-LDN on CartPole and MuJoCo",
        "",
        "Generated by `python -m experiments.paper.report` from the result files beside it; do not "
        "edit by hand. The paper's numbers are those of docs/paper.md.",
        "",
    ]
    for section in (setup(data, scale), summary, *body):
        lines += render_section(section)
    # The studies run on their own (experiments/paper/headline.py, sac.py, sac_rules.py,
    # locomotion.py, family.py, a2c.py, a2c_model.py and branched.py); the confirmatory ones
    # first.
    studies = (
        "headline",
        "sac",
        "sac-rules",
        "locomotion",
        "family",
        "a2c/user-command",
        "a2c/a2c",
    )
    studies += ("a2c-model", "branched")
    for study in studies:
        text = results / (f"{study}/{study}.md" if "/" not in study else f"{study}.md")
        if text.exists():
            lines += ["", text.read_text().strip(), ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    scale, results = common.parse_args(argv, __doc__)
    results.mkdir(parents=True, exist_ok=True)
    (results / "REPORT.md").write_text(render(results, scale))
    print(f"wrote {results / 'REPORT.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
