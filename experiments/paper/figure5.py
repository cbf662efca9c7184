"""Figure 5: the distribution of the learning degree over imagined steps during cartpole-v2
training (the Table 2 runs: MBRL-LDN, and A2C-Model whose imagination ignores LD).

    python -m experiments.paper.figure5 [--scale cpu|cpu-full|paper] [--smoke] [--results DIR]

Training records, per iteration, how many imagined steps fell in each LD bin of width 0.1
(the `ld_histogram` metric). Two x axes, both per seed and summed over seeds, in bins of
500 steps:
- cumulative imagined steps (summed over workers): an iteration's counts are spread over the
  step bins its imagined steps span, in proportion (within one iteration the order of steps
  is not recorded);
- cumulative real env steps: an iteration's imagined steps are placed at the real step count
  at which they were imagined (after that iteration's real episodes).
Writes figure5.png and figure5.json into DIR/figure5/.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from experiments.paper import cache, common
from ldn_jax.learning_degree import LD_BINS

STEP_BIN = 500
MAX_BINS = 400
"""A longer axis (A2C-Model imagines up to 8,000 steps per iteration) gets the smallest
multiple of `STEP_BIN` that keeps it within this many bins, to keep figure5.json small."""
ALGOS = ("ldn", "a2c-model")
EARLY = 10_000
"""The paper: LD rises over the first 10k steps, then is mostly near 1."""


def spread(counts: np.ndarray, cumulative: np.ndarray, width: int) -> np.ndarray:
    """Per-iteration counts `[N, B]` -> `[steps // width + 1, B]` on a step axis, each
    iteration's counts spread over the bins of the steps it spans (`cumulative` `[N]`: steps
    after each iteration), in proportion to the overlap."""
    total = int(cumulative[-1]) if cumulative.size else 0
    out = np.zeros((total // width + 1, counts.shape[1]))
    start = np.concatenate([[0], cumulative[:-1]])
    for i in range(len(counts)):
        lo, hi = float(start[i]), float(cumulative[i])
        if hi <= lo:
            continue
        for b in range(int(lo // width), int(np.ceil(hi / width))):
            overlap = min(hi, (b + 1) * width) - max(lo, b * width)
            if overlap > 0:
                out[b] += counts[i] * overlap / (hi - lo)
    return out


def place(counts: np.ndarray, at: np.ndarray, width: int) -> np.ndarray:
    """Per-iteration counts `[N, B]` placed in the bin of `at` `[N]` (steps, >= 1)."""
    out = np.zeros((int(at.max()) // width + 1 if at.size else 1, counts.shape[1]))
    np.add.at(out, (np.maximum(at, 1) - 1) // width, counts)
    return out


def bin_width(total: float) -> int:
    return STEP_BIN * max(1, int(np.ceil(total / STEP_BIN / MAX_BINS)))


def _pad_sum(parts: list[np.ndarray]) -> np.ndarray:
    rows = max(p.shape[0] for p in parts)
    return sum(np.pad(p, ((0, rows - p.shape[0]), (0, 0))) for p in parts)


def histograms(history: dict) -> dict:
    """Both step axes for one run (K index 0), summed over seeds; frozen iterations of a
    diverged seed are left out."""
    counts = history["ld_histogram"][0]  # [S, N, B]
    valid = history["failure"][0] == 0
    imagined, real = [], []
    imagined_width = bin_width(history["imagined_steps"][0, :, -1].max())
    real_width = bin_width(history["env_steps"][0, :, -1].max())
    for seed in range(counts.shape[0]):
        ok = valid[seed]
        c = counts[seed][ok]
        imagined.append(spread(c, history["imagined_steps"][0, seed][ok], imagined_width))
        real.append(place(c, history["env_steps"][0, seed][ok], real_width))
    imagined, real = _pad_sum(imagined), _pad_sum(real)
    total = imagined.sum(0)
    early = imagined[: EARLY // imagined_width].sum(0)
    late = imagined[EARLY // imagined_width :].sum(0)
    fraction = lambda c, lo, hi: float(c[lo:hi].sum() / c.sum()) if c.sum() else None
    return {
        "seeds": int(counts.shape[0]),
        "imagined_steps_per_seed": history["imagined_steps"][0, :, -1].tolist(),
        "imagined_axis": {"step_bin": imagined_width, "counts": np.round(imagined, 2).tolist()},
        "real_axis": {"step_bin": real_width, "counts": np.round(real, 2).tolist()},
        "fraction_ld_below_0.1": fraction(total, 0, 1),
        "fraction_ld_at_least_0.9": fraction(total, LD_BINS - 1, LD_BINS),
        "first_10k_fraction_ld_at_least_0.9": fraction(early, LD_BINS - 1, LD_BINS),
        "after_10k_fraction_ld_at_least_0.9": fraction(late, LD_BINS - 1, LD_BINS),
        "ld_mean_first_iterations": float(np.nanmean(history["ld_mean"][0][:, :10])),
        "ld_mean_last_iterations": float(np.nanmean(history["ld_mean"][0][:, -10:])),
    }


def _panel(ax, axis: dict, xlabel: str, title: str):
    counts, width = np.asarray(axis["counts"]), axis["step_bin"]
    column = counts.sum(1, keepdims=True)
    fraction = np.where(column > 0, counts / np.maximum(column, 1e-12), np.nan)
    x = np.arange(counts.shape[0] + 1) * width
    y = np.linspace(0, 1, LD_BINS + 1)
    mesh = ax.pcolormesh(x, y, fraction.T, vmin=0, vmax=1, cmap="viridis")
    ax.set_xlabel(f"{xlabel} (bins of {width})")
    ax.xaxis.set_major_formatter(lambda v, _: f"{v / 1000:g}k" if v >= 1000 else f"{v:g}")
    ax.set_ylabel("learning degree")
    ax.set_title(title, fontsize=9)
    return mesh


def figure(data: dict, env: str, path: Path) -> None:
    algos = list(data)
    fig, axes = plt.subplots(
        len(algos), 2, figsize=(11, 3.8 * len(algos)), dpi=120, squeeze=False, layout="constrained"
    )
    mesh = None
    for row, algo in zip(axes, algos, strict=True):
        d = data[algo]
        name = common.PAPER_ALGOS.get(algo, algo)
        steps = round(np.sum(d["imagined_axis"]["counts"]))
        mesh = _panel(
            row[0],
            d["imagined_axis"],
            "cumulative imagined steps per seed",
            f"{name}: {steps:,} imagined steps over {d['seeds']} seeds",
        )
        _panel(
            row[1],
            d["real_axis"],
            "cumulative real env steps per seed",
            f"{name}: the same steps by when they were imagined",
        )
    fig.colorbar(mesh, ax=axes, label="fraction of the bin's imagined steps", shrink=0.8)
    fig.suptitle(f"Learning degree of imagined steps, {env} (LD bins of 0.1)", fontsize=10)
    fig.savefig(path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    scale, results = common.parse_args(argv, __doc__)
    data = {}
    for entry in cache.collect_runs((scale.ld_env,), ALGOS, scale, results):
        data[entry["algo"]] = histograms(cache.load_history(entry["dir"]))
    out = common.out_dir(results, "figure5")
    record = {
        **common.scale_record(scale),
        "env": scale.ld_env,
        "k": 1.0,
        "step_bin": STEP_BIN,
        "max_bins": MAX_BINS,
        "ld_bin_edges": np.linspace(0, 1, LD_BINS + 1).round(2).tolist(),
        "axes": "imagined_axis.counts[i][j]: imagined steps (summed over seeds) whose "
        "cumulative imagined step index lies in bin i (width imagined_axis.step_bin: step_bin, "
        "or a multiple keeping max_bins) and whose LD lies in bin j; real_axis: the same "
        "steps binned by the cumulative real env steps at which they were imagined",
        "runs": data,
    }
    common.write_json(out / "figure5.json", record, compact=True)
    figure(data, scale.ld_env, out / "figure5.png")
    print(f"wrote {out}/figure5.png, figure5.json")
    return 0


if __name__ == "__main__":
    sys.exit(common.script(main))
