"""Branched imagination (`imagine.start` "real", ours, in the style of MBPO): `branches`
rollouts in M1 side by side, each from a state drawn from the real buffer R and cut after the
`cut` (or sooner by the stop rule), the next drawn as one ends, until the iteration has
imagined `ratio` steps per real step; the learner updates on every n steps of them,
with `real_share` of real rows beside. What those updates may move is `ImaginedUpdates`."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import jax
import jax.numpy as jnp

from ldn_jax.buffer import buffer_sample_recent
from ldn_jax.config import ImagineConfig
from ldn_jax.imagination import (
    first_step_statistic,
    ld_history,
    macura_threshold,
    scheduled_horizon,
)
from ldn_jax.learners.base import Segment
from ldn_jax.rollout import Batch, Episodes, Player, play_batch
from ldn_jax.stages.imagine import world_of
from ldn_jax.stages.parts import Parts, RealPlay, TrainState

Array = jax.Array

POLICY = ("actor", "log_std")
"""The learner's params entries that make up the policy (the rest is the critic)."""


@dataclass(frozen=True)
class ImaginedUpdates:
    """What the updates on imagined rows may move: the one place that decides it
    (`imagine.updates`, `std`, `actor_step`, `epochs`)."""

    frozen: tuple[str, ...] = ()
    """Params entries whose gradients and steps are zero there (critic-only updates), so a
    global-norm clip and PPO's KL guard see the rest alone."""
    kept: tuple[str, ...] = ()
    """Params entries left as they were, with their optimiser moments (`rollout.keep_leaves`)."""
    policy_step: float = 1.0
    """The policy's step there, as a share of its own."""
    epochs: int = 0
    """PPO's passes over imagined rows (0: the learner's own)."""

    @classmethod
    def of(cls, config: ImagineConfig) -> ImaginedUpdates:
        critic_only = config.updates == "critic"
        kept = POLICY if critic_only else ("log_std",) if config.std == "real" else ()
        return cls(
            frozen=POLICY if critic_only else (),
            kept=kept,
            policy_step=config.actor_step,
            epochs=config.epochs,
        )

    def learner(self, learner):
        """`learner` as it updates on imagined rows."""
        return (
            learner.freezing(self.frozen).scaling(POLICY, self.policy_step).with_epochs(self.epochs)
        )


@dataclass(frozen=True)
class Branching:
    """One iteration's branches before anyone plays them: what both branch stages share."""

    start: tuple
    """`(obs, history)`: the first rollouts' start states, drawn from R."""
    world: Callable
    """M1 as the world, stopped by the run's rule."""
    horizon: Array | int
    """The cut: `cut`, or MBPO's scheduled horizon."""
    batch: Batch


def branching(parts: Parts, state: TrainState, keys: tuple, gain: Array, real: RealPlay):
    """The iteration's `Branching`: starts from R, the world, the cut and the row quota;
    `keys`: the starts' and the macura threshold's."""
    config = parts.config.imagine
    k_start, k_first = keys
    history = ld_history(parts.dynamics, config.branches)
    draw = lambda key: _draw(config, state, key)
    obs = draw(k_start)
    rule = parts.config.stop_rule
    threshold = None
    if rule == "macura":  # from the first step of this iteration's starts
        threshold = _macura_threshold(parts, state, obs, k_first)
    played = real.episodes.lengths.sum()
    horizon = config.cut
    if rule == "mbpo":
        horizon = scheduled_horizon(parts.config.stop, state.env_steps + played)
    batch = Batch(
        reset=lambda key: (draw(key), history),
        segments=parts.config.branch_segments(parts.real.max_steps),
        rows=jnp.ceil(config.ratio * played),
    )
    return Branching((obs, history), world_of(parts, state, gain, threshold), horizon, batch)


def branches(
    parts: Parts, state: TrainState, key: Array, gain: Array, real: RealPlay
) -> tuple[TrainState, Episodes]:
    """The iteration's branches and the on-policy learner's updates on them."""
    k_start, k_play, k_first = jax.random.split(key, 3)
    plan = branching(parts, state, (k_start, k_first), gain, real)
    updates = ImaginedUpdates.of(parts.config.imagine)
    player = Player(
        updates.learner(parts.learner),
        plan.world,
        parts.real.max_steps,
        horizon=plan.horizon,
        keep=updates.kept,
        mix=_real_rows(parts.config.imagine, real.episodes.steps, real.episodes.lengths),
    )
    learner, imagined = play_batch(k_play, state.learner, player, plan.start, plan.batch)
    return state.replace(learner=learner), imagined


def remembered(
    parts: Parts, state: TrainState, key: Array, gain: Array, real: RealPlay
) -> tuple[TrainState, Episodes]:
    """MBPO's rollouts for an off-policy learner: `branches` rollouts played by the current
    policy, one from each start drawn from R, each until its horizon, the stop rule or a
    predicted termination ends it (none follows it: MBPO's layout, so the rows grow with the
    horizon and every rule decides how far the same starts go); no update on them here.
    Their rows go to the learner's model memory (`SACLearner.remember`), which its updates
    during the next real play draw from."""
    k_start, k_play, k_first = jax.random.split(key, 3)
    plan = branching(parts, state, (k_start, k_first), gain, real)
    player = Player(parts.learner, plan.world, parts.real.max_steps, horizon=plan.horizon)
    player = dataclasses.replace(player, learn=False)
    n_steps = parts.learner.config.n_steps
    batch = Batch(segments=-(-parts.config.branch_horizon // n_steps))
    _, imagined = play_batch(k_play, state.learner, player, plan.start, batch)
    return state.replace(learner=parts.learner.remember(state.learner, imagined.steps)), imagined


def _draw(config: ImagineConfig, state: TrainState, key: Array) -> Array:
    """`branches` start states from R (from its newest `start_window` where set)."""
    buffer = state.buffer
    if config.start_window:
        return buffer_sample_recent(buffer, key, config.branches, config.start_window).obs
    index = jax.random.randint(key, (config.branches,), 0, jnp.maximum(buffer.size, 1))
    return buffer.data.obs[index]


def _macura_threshold(parts: Parts, state: TrainState, obs: Array, key: Array) -> Array:
    """MACURA's cut for this iteration, from the first imagined step of its starts `obs`."""
    config = parts.config.stop
    k_act, k_model = jax.random.split(key)
    learner = parts.learner
    action = learner.env_action(learner.act(state.learner.params, k_act, obs))
    first = first_step_statistic(
        parts.dynamics, state.model, obs, parts.model_action(action), k_model
    )
    return macura_threshold(first, config.macura_quantile, config.macura_scale)


def _real_rows(config: ImagineConfig, steps: Segment, lengths: Array):
    """`Player.mix` for `real_share`: beside the `branches` imagined rollouts of each
    segment, R = round(branches x share / (1 - share)) windows of n real steps of this
    iteration (a worker and a start within its played steps, drawn at random); None for a
    share of 0."""
    share = config.real_share
    count = round(config.branches * share / (1 - share))
    if count == 0:
        return None

    def mix(key: Array, segment: Segment) -> Segment:
        n = segment.weight.shape[0]
        k_worker, k_start = jax.random.split(key)
        worker = jax.random.randint(k_worker, (count,), 0, lengths.shape[0])
        room = jnp.maximum(lengths[worker] - n, 0) + 1
        start = (jax.random.uniform(k_start, (count,)) * room).astype(jnp.int32)
        start = jnp.minimum(start, steps.weight.shape[0] - n)

        def window(x: Array) -> Array:
            one = lambda w, t: jax.lax.dynamic_slice_in_dim(x[:, w], t, n, 0)
            return jax.vmap(one, out_axes=1)(worker, start)

        real = jax.tree.map(window, steps)
        return jax.tree.map(lambda a, b: jnp.concatenate([a, b], axis=1), segment, real)

    return mix
