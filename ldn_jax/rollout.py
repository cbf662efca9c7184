"""Workers playing in segments of n steps, with a learner update after each.

The same code plays real episodes (the world is the env) and imagined ones (the world is
M1): a world is a pure `step(key, world_state, obs, action)`; a `Player` names the learner,
the world and the step limit. Three entry points:
- `play_episodes`: one episode per worker. Workers whose episode has ended stay in the batch
  with weight 0; nothing branches on them.
- `play_batch`: a worker whose episode ends starts the next at once from `reset` (no
  weight-0 rows), until every worker has ended at least one episode, or has played its
  `quota` of episodes.
- `play_steps` (schedule "steps"): a fixed number of segments from where the workers stand,
  each worker starting its next episode as one ends, so that nothing idles; the episodes
  carry over from one call to the next (`Workers`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from ldn_jax.learners.base import LearnerState, Segment

Array = jax.Array

WorldStep = Callable[
    [Array, Any, Array, Array, Array], tuple[Array, Any, Array, Array, Array, dict]
]
"""`(key, world_state, obs [W, d], action [W] or [W, a], alive [W]) -> (next_obs,
world_state, reward [W], terminated [W], truncated [W], extras {name: [W]})`. The action is
the one the env executes (continuous actions clipped to the bounds); segments keep the
policy's sample. `alive` says which workers' steps count (a rule ranking the running
imagined rollouts reads it); a world may ignore it."""

Reset = Callable[[Array], tuple[Array, Any]]
"""`reset(key) -> (obs [W, d], world_state)`: fresh starts for every worker."""


@dataclass(frozen=True)
class Player:
    """Who plays in which world: the static part of a batch's play (one compiled program)."""

    learner: Any
    """The learner whose policy acts (`ldn_jax.learners`)."""
    world_step: WorldStep
    max_steps: int
    """An episode still running after this many steps is truncated."""
    learn: bool = True
    """Update the learner after each segment. False: only play (the learner's parameters
    act throughout and are returned unchanged; `losses` is empty), for a learner that
    learns from the whole batch later."""
    observe: bool = False
    """Real episodes: each segment goes into the learner's running statistics of observations
    and returns (`AgentConfig.normalize_obs`, `normalize_reward`) before it learns from it."""
    horizon: Any = None
    """A cut below `max_steps` that may be a traced int (MBPO's schedule): an episode still
    running after this many steps is truncated; None: `max_steps` alone."""
    keep: tuple[str, ...] = ()
    """Parameters the updates leave as they were, with their optimiser state (the names of
    top-level entries of the learner's params, e.g. "log_std")."""
    mix: Callable[[Array, Segment], Segment] | None = None
    """`mix(key, segment) -> segment`: what the learner learns from instead of each played
    segment `[n, W]` (branched imagination adds real rows beside the imagined ones); the
    played segment is still what the batch returns."""


@struct.dataclass
class EpisodeCarry:
    learner: LearnerState
    obs: Array
    """`[W, obs_size]`; frozen at the last observation once a worker's episode ends."""
    world: Any
    alive: Array
    """`[W]` bool: the worker's steps count (its first episode is still running, or it
    auto-resets)."""
    finished: Array
    """`[W]` bool: the worker has ended at least one episode."""
    time: Array
    """`[W]` int32: steps taken in the worker's current episode."""
    owed: Array | None = None
    """`[W]` int32: episodes the worker has still to end (`play_episodes`' `quota`); None
    without a quota."""


@struct.dataclass
class Episodes:
    """What one batch of W episodes produced."""

    steps: Segment
    """Every step, `[T', W, ...]` with T' = max_steps rounded up to whole segments."""
    extras: dict
    """World extras per step, `[T', W]`."""
    losses: dict
    """Learner losses averaged over segments that had live steps."""

    @property
    def returns(self) -> Array:
        return jnp.sum(self.steps.reward * self.steps.weight, axis=0)

    @property
    def lengths(self) -> Array:
        return jnp.sum(self.steps.weight, axis=0).astype(jnp.int32)

    @property
    def ended(self) -> Array:
        """Episodes that ended, per worker `[W]`: 1 each, unless the workers auto-reset."""
        return jnp.sum(self.steps.done * self.steps.weight, axis=0)

    def mean_episode(self) -> tuple[Array, Array]:
        """Mean length and mean return of the episodes that ended, `([], [])`.

        Without auto-reset these are `lengths.mean()` and `returns.mean()`; with it, the
        steps of an episode cut off by the batch's end count in neither.
        """
        weight, done = self.steps.weight, self.steps.done * self.steps.weight
        # A step belongs to an ended episode if its worker ends one at or after it.
        in_ended = jnp.cumsum(done[::-1], axis=0)[::-1] > 0
        episodes = jnp.maximum(self.ended.sum(), 1.0)
        length = jnp.where(in_ended, weight, 0.0).sum() / episodes
        total = jnp.where(in_ended, self.steps.reward * weight, 0.0).sum()
        return length, total / episodes


def _segment_fn(
    player: Player, reset: Reset | None
) -> Callable[[EpisodeCarry, Array], tuple[EpisodeCarry, tuple]]:
    """`(carry, key) -> (carry, (transitions, extras, losses))`: n steps of every worker,
    then the learner's update; with `reset`, a worker whose episode ends starts the next."""
    learner, world_step, max_steps = player.learner, player.world_step, player.max_steps
    learn, observe, horizon, mix = player.learn, player.observe, player.horizon, player.mix
    n_steps = learner.config.n_steps

    def step(carry: EpisodeCarry, key: Array):
        k_act, k_world = jax.random.split(key)
        if observe:  # real play: the learner may act otherwise at a run's start (`behave`)
            action = learner.behave(carry.learner, k_act, carry.obs)
        else:
            action = learner.act(carry.learner.params, k_act, carry.obs)
        if reset is not None:
            k_world, k_reset = jax.random.split(k_world)
        next_obs, world, reward, terminated, truncated, extras = world_step(
            k_world, carry.world, carry.obs, learner.env_action(action), carry.alive
        )
        limit = carry.time + 1 >= max_steps
        if horizon is not None:
            limit = limit | (carry.time + 1 >= horizon)
        truncated = (truncated | limit) & ~terminated
        done = terminated | truncated
        transition = Segment(
            obs=carry.obs,
            action=action,
            reward=reward,
            next_obs=next_obs,
            terminated=terminated,
            done=done,
            weight=carry.alive.astype(jnp.float32),
        )
        finished = carry.finished | (carry.alive & done)
        owed = carry.owed
        if reset is None:  # a finished worker keeps its last observation, masked
            alive = carry_on = carry.alive & ~done
            restart_obs, restart_world = carry.obs, carry.world
        else:  # a finished worker starts its next episode
            alive, carry_on = carry.alive, ~done
            restart_obs, restart_world = reset(k_reset)
            if owed is not None:  # it plays on until it owes none
                owed = owed - (carry.alive & done)
                alive, finished = carry.alive & (owed > 0), owed <= 0
        select = lambda new, old: jnp.where(
            carry_on.reshape((-1,) + (1,) * (new.ndim - 1)), new, old
        )
        carry = carry.replace(
            obs=select(next_obs, restart_obs),
            world=jax.tree.map(select, world, restart_world),
            alive=alive,
            finished=finished,
            time=jnp.where(carry_on, carry.time + 1, 0),
            owed=owed,
        )
        return carry, (transition, extras)

    def segment(carry: EpisodeCarry, key: Array):
        k_steps, k_update = jax.random.split(key)
        carry, (transitions, extras) = jax.lax.scan(step, carry, jax.random.split(k_steps, n_steps))
        if observe:
            carry = carry.replace(learner=learner.observe(carry.learner, transitions))
        if not learn:
            return carry, (transitions, extras, {})
        learned = transitions
        if mix is not None:
            k_update, k_mix = jax.random.split(k_update)
            learned = mix(k_mix, transitions)
        learner_state, losses = learner.update(carry.learner, learned, k_update)
        if player.keep:
            learner_state = keep_leaves(learner_state, carry.learner, player.keep)
        return carry.replace(learner=learner_state), (transitions, extras, losses)

    return segment


def keep_leaves(new: Any, old: Any, names: tuple[str, ...]) -> Any:
    """`new` with every leaf found under a dict key in `names` taken from `old`: a parameter
    and, in the optimiser's state, its moments."""

    def pick(path, fresh, kept):
        return kept if any(getattr(k, "key", None) in names for k in path) else fresh

    return jax.tree_util.tree_map_with_path(pick, new, old)


def play_episodes(
    key: Array, learner_state: LearnerState, player: Player, obs: Array, world: Any
) -> tuple[LearnerState, Episodes]:
    """One episode on each of W workers from `obs [W, d]` and `world`, the learner updated
    every `n_steps` steps (unless `player.learn` is False). An episode ends on `terminated`,
    on `truncated`, or after `player.max_steps` steps; the loop ends once every worker's
    has."""
    return _play(key, learner_state, player, obs, world, Batch())


@dataclass(frozen=True)
class Batch:
    """How `play_batch` lays out its episodes (fields may hold traced arrays)."""

    reset: Reset | None = None
    """`reset(key) -> (obs, world)`: the next episode's start once one ends; None: each
    worker plays one episode (`play_episodes`)."""
    quota: Array | None = None
    """`[W]` int: worker w plays `quota[w]` episodes one after the other (none: all its rows
    weight 0), then idles masked."""
    segments: int | None = None
    """The most segments played (default: one episode's, `max_steps` rounded up), where the
    episode still running is cut."""
    rows: Array | None = None
    """(may be traced) instead of until every worker has ended an episode, segments are
    played until at least this many rows (n x W per segment) have been, at most `segments`
    (branched imagination's quota of imagined steps)."""


def play_batch(
    key: Array,
    learner_state: LearnerState,
    player: Player,
    start: tuple[Array, Any],
    batch: Batch,
) -> tuple[LearnerState, Episodes]:
    """Episodes back to back on each of W workers: the first from `start` = (obs, world),
    each next one from `batch.reset` as soon as one ends, so every row of the batch is live.
    Segments are played until every worker has ended an episode (at least one segment), or
    as `batch` says. An episode still running at the batch's end is cut there: its last step
    bootstraps, as at any segment's end."""
    return _play(key, learner_state, player, *start, batch)


def _play(key, learner_state, player, obs, world, batch: Batch):
    """`play_episodes` (no `reset`) and `play_batch`."""
    reset, quota, segments, rows = batch.reset, batch.quota, batch.segments, batch.rows
    learner, max_steps = player.learner, player.max_steps
    n_steps = learner.config.n_steps
    n_segments = segments or math.ceil(max_steps / n_steps)
    workers = obs.shape[0]
    segment = _segment_fn(player, reset)

    carry = EpisodeCarry(
        learner=learner_state,
        obs=obs,
        world=world,
        alive=jnp.ones((workers,), bool) if quota is None else quota > 0,
        finished=jnp.zeros((workers,), bool) if quota is None else quota <= 0,
        time=jnp.zeros((workers,), jnp.int32),
        owed=None if quota is None else quota.astype(jnp.int32),
    )
    keys = jax.random.split(key, n_segments)
    # The loop over segments stops once every worker has ended an episode. Without `reset`
    # the mask alone defines the result: a segment with no live step changes nothing
    # (`keep_if_any`), so skipping it is pure savings. Under vmap the loop runs until the
    # whole batch is done.
    out_shape = jax.eval_shape(segment, carry, keys[0])[1]
    outputs = jax.tree.map(lambda x: jnp.zeros((n_segments, *x.shape), x.dtype), out_shape)

    def cond(loop):
        index, carry, _ = loop
        if rows is not None:
            return (index < n_segments) & (index * n_steps * workers < rows)
        return (index < n_segments) & ~carry.finished.all()

    def body(loop):
        index, carry, outputs = loop
        carry, out = segment(carry, keys[index])
        outputs = jax.tree.map(
            lambda buf, x: jax.lax.dynamic_update_index_in_dim(buf, x, index, 0), outputs, out
        )
        return index + 1, carry, outputs

    _, carry, (steps, extras, losses) = jax.lax.while_loop(cond, body, (0, carry, outputs))
    live = (steps.weight.sum(axis=(1, 2)) > 0).astype(jnp.float32)
    flat = lambda x: x.reshape((n_segments * n_steps, *x.shape[2:]))
    losses = jax.tree.map(lambda x: (x * live).sum() / jnp.maximum(live.sum(), 1.0), losses)
    episodes = Episodes(
        steps=jax.tree.map(flat, steps), extras=jax.tree.map(flat, extras), losses=losses
    )
    return carry.learner, episodes


@struct.dataclass
class Workers:
    """W workers of the real env between iterations (schedule "steps"): each is somewhere in
    an episode that carries over into the next iteration."""

    obs: Array
    """`[W, obs_size]`: the observation each worker acts on next."""
    world: Any
    """The env states, `[W, ...]`."""
    time: Array
    """`[W]` int32: steps taken in the worker's current episode."""
    total: Array
    """`[W]` float32: the env's reward summed over the current episode so far."""


def workers_init(obs: Array, world: Any) -> Workers:
    """Workers at the start of their first episodes."""
    zeros = jnp.zeros(obs.shape[:1])
    return Workers(obs=obs, world=world, time=zeros.astype(jnp.int32), total=zeros)


@struct.dataclass
class Completed:
    """The episodes that ended during a `play_steps` call, at the step each ended: `[T, W]`,
    valid where `ended` (the (step, worker) order is completion order, ties by worker)."""

    ended: Array
    """`[T, W]` bool: the worker's episode ended at this step."""
    returns: Array
    """`[T, W]`: the episode's return, its steps in earlier calls included (0 where not
    ended)."""
    lengths: Array
    """`[T, W]` int32: the episode's length (0 where not ended)."""


def play_steps(
    key: Array,
    learner_state: LearnerState,
    player: Player,
    workers: Workers,
    segments: int,
    reset: Reset,
) -> tuple[LearnerState, Episodes, Completed, Workers]:
    """Play `segments` segments of n steps on each of W workers from where they are,
    updating the learner after each (schedule "steps"). A worker whose episode ends
    (`terminated`, `truncated`, or `player.max_steps` steps) starts the next from
    `reset(key)` at once, so every row counts (weight 1) and the loop has a fixed length.
    Returns the learner, the steps `[T, W, ...]` (T = segments x n), the episodes that
    ended, and the workers where they stand."""
    segment = _segment_fn(player, reset)
    n = workers.obs.shape[0]
    carry = EpisodeCarry(
        learner=learner_state,
        obs=workers.obs,
        world=workers.world,
        alive=jnp.ones((n,), bool),
        finished=jnp.zeros((n,), bool),
        time=workers.time,
    )
    carry, (steps, extras, losses) = jax.lax.scan(segment, carry, jax.random.split(key, segments))
    flat = lambda x: x.reshape((-1, *x.shape[2:]))
    steps, extras = jax.tree.map(flat, steps), jax.tree.map(flat, extras)
    losses = jax.tree.map(jnp.mean, losses)

    def count(running, step):  # the episodes' returns and lengths as they end
        total, time = running
        reward, done = step
        total, time = total + reward, time + 1
        kept = (jnp.where(done, 0.0, total), jnp.where(done, 0, time))
        return kept, (jnp.where(done, total, 0.0), jnp.where(done, time, 0))

    (total, time), (returns, lengths) = jax.lax.scan(
        count, (workers.total, workers.time), (steps.reward, steps.done)
    )
    workers = Workers(obs=carry.obs, world=carry.world, time=time, total=total)
    completed = Completed(ended=steps.done, returns=returns, lengths=lengths)
    episodes = Episodes(steps=steps, extras=extras, losses=losses)
    return carry.learner, episodes, completed, workers
