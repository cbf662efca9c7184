"""Pure summaries of training metrics (numpy, host side)."""

from __future__ import annotations

import numpy as np


def threshold_crossing(
    moving_after: np.ndarray,
    lengths: np.ndarray,
    env_steps: np.ndarray,
    threshold: float,
    ended: np.ndarray | None = None,
    steps_at: np.ndarray | None = None,
) -> tuple[int, int, int] | None:
    """Where the moving return first reaches `threshold`, for one seed and K.

    Args:
      moving_after: `[I, C]` moving return after each episode, in completion order.
      lengths: `[I, C]` the episodes' lengths, in the same order.
      env_steps: `[I]` cumulative real env steps at the end of each iteration.
      ended, steps_at: schedule "steps" (`Config.schedule`): `[I, C]` which entries are
        episodes that ended, and the run's real env steps when each did; None: every entry
        is an episode (schedule "episodes").

    Returns `(episode, env_steps, iteration)`: the 1-based global episode count, the real env
    steps taken by all workers when it completed (schedule "episodes": workers step in
    lockstep, so that is steps-before-iteration + sum_w min(L_w, L_episode)), and its
    0-based iteration; or None.
    """
    if ended is not None:
        hits = np.argwhere((moving_after >= threshold) & ended)
        if hits.size == 0:
            return None
        iteration, j = (int(v) for v in hits[0])
        episode = int(ended[:iteration].sum() + ended[iteration, : j + 1].sum())
        return episode, int(steps_at[iteration, j]), iteration
    hits = np.argwhere(moving_after >= threshold)
    if hits.size == 0:
        return None
    iteration, j = (int(v) for v in hits[0])
    workers = moving_after.shape[1]
    length = lengths[iteration]
    before = int(env_steps[iteration]) - int(length.sum())
    steps = before + int(np.minimum(length, length[j]).sum())
    return iteration * workers + j + 1, steps, iteration


def run_crossing(history: dict, run: tuple, threshold: float) -> tuple[int, int, int] | None:
    """`threshold_crossing` of one run of a history `{name: [..., N, ...]}`: `run` indexes
    its leading axes (`(k, seed)` of a run's history)."""
    pick = lambda name: history[name][run] if name in history else None
    return threshold_crossing(
        pick("moving_after"),
        pick("lengths"),
        pick("env_steps"),
        threshold,
        pick("ended"),
        pick("steps_at"),
    )


def completed_returns(history: dict, run: tuple) -> np.ndarray:
    """One run's moving return after each of its episodes, in completion order `[E]`."""
    after = history["moving_after"][run]
    if "ended" in history:
        return after[history["ended"][run]]
    return after.reshape(-1)


def mean_band(curves: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean and 95% confidence band (normal approximation) over axis 0 of `[S, T]`."""
    mean = curves.mean(0)
    if curves.shape[0] < 2:
        return mean, mean, mean
    half = 1.96 * curves.std(0, ddof=1) / np.sqrt(curves.shape[0])
    return mean, mean - half, mean + half
