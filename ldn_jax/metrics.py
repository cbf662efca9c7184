"""Pure summaries of training metrics (numpy, host side)."""

from __future__ import annotations

import numpy as np


def threshold_crossing(
    moving_after: np.ndarray, lengths: np.ndarray, env_steps: np.ndarray, threshold: float
) -> tuple[int, int, int] | None:
    """Where the moving return first reaches `threshold`, for one seed and K.

    Args:
      moving_after: `[I, W]` moving return after each episode, in completion order.
      lengths: `[I, W]` the episodes' lengths, in the same order.
      env_steps: `[I]` cumulative real env steps at the end of each iteration.

    Returns `(episode, env_steps, iteration)`: the 1-based global episode count, the real env
    steps taken by all workers when it completed (workers step in lockstep, so that is
    steps-before-iteration + sum_w min(L_w, L_episode)), and its 0-based iteration; or None.
    """
    hits = np.argwhere(moving_after >= threshold)
    if hits.size == 0:
        return None
    iteration, j = (int(v) for v in hits[0])
    workers = moving_after.shape[1]
    length = lengths[iteration]
    before = int(env_steps[iteration]) - int(length.sum())
    steps = before + int(np.minimum(length, length[j]).sum())
    return iteration * workers + j + 1, steps, iteration


def mean_band(curves: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean and 95% confidence band (normal approximation) over axis 0 of `[S, T]`."""
    mean = curves.mean(0)
    if curves.shape[0] < 2:
        return mean, mean, mean
    half = 1.96 * curves.std(0, ddof=1) / np.sqrt(curves.shape[0])
    return mean, mean - half, mean + half
