"""What every learner shares: the masked segment it consumes and the actor-critic it trains."""

from __future__ import annotations

import copy

import jax
import jax.numpy as jnp
import optax
from flax import struct

from ldn_jax.config import AgentConfig, Config
from ldn_jax.networks import MLP

Array = jax.Array


REWARD_CLIP = 10.0
"""Normalised rewards (`AgentConfig.normalize_reward`) are clipped to +-this (SB3's default)."""


@struct.dataclass
class Segment:
    """Transitions of W workers over n steps, time-major: every field `[n, W, ...]`."""

    obs: Array
    action: Array
    reward: Array
    next_obs: Array
    terminated: Array
    """The next state is terminal: no future value, no bootstrap."""
    done: Array
    """The episode ended here (terminated, truncated, or stopped by the LD draw)."""
    weight: Array
    """1.0 for a live transition, 0.0 for a masked one (its worker's episode had ended)."""


@struct.dataclass
class LearnerState:
    params: dict
    opt_state: tuple


def zero_masked(tree, weight: Array):
    """Zero every leaf of `tree` (leaves shaped `[*weight.shape, ...]`) where `weight` is 0."""
    live = weight > 0

    def zero(x: Array) -> Array:
        mask = live.reshape(live.shape + (1,) * (x.ndim - live.ndim))
        return jnp.where(mask, x, jnp.zeros_like(x))

    return jax.tree.map(zero, tree)


def canonical(segment: Segment) -> Segment:
    """Zero every field of the masked steps.

    Whatever a masked step holds (a frozen observation, a model's inf, NaN), the learner then
    sees the same finite numbers, so its forward and backward passes cannot pick up a NaN
    through a `0 * NaN` and masked steps change nothing, to the bit.
    """
    return zero_masked(segment, segment.weight)


def training_reward(segment: Segment, config: AgentConfig) -> Array:
    """The reward the learner trains on: the env's, or `terminal_reward` on terminal steps,
    times `reward_scale`."""
    reward = segment.reward
    if config.terminal_reward is not None:
        reward = jnp.where(segment.terminated, config.terminal_reward, reward)
    scale = config.reward_scale  # a traced array in a sweep
    return reward if isinstance(scale, float) and scale == 1.0 else reward * scale


def gae(
    reward: Array,
    value: Array,
    next_value: Array,
    terminated: Array,
    done: Array,
    discounts: tuple[float, float],
) -> Array:
    """Generalised advantage estimates of one segment, `[n, W] -> [n, W]`, with `discounts`
    = (gamma, lambda).

    delta_t = r_t + gamma * (1 - terminated_t) * V(s'_t) - V(s_t);
    A_t = delta_t + gamma * lam * (1 - done_t) * A_{t+1}, and A_{n} = 0 past the segment.
    A truncation (time limit, LD stop) bootstraps from V(s'_t) and ends the recursion; a
    termination does neither.
    """
    gamma, lam = discounts
    delta = reward + gamma * (1.0 - terminated.astype(reward.dtype)) * next_value - value

    def backward(following, step):
        delta, done = step
        advantage = delta + gamma * lam * jnp.where(done, 0.0, following)
        return advantage, advantage

    _, advantages = jax.lax.scan(backward, jnp.zeros_like(delta[-1]), (delta, done), reverse=True)
    return advantages


def worker_mean(x: Array, weight: Array) -> Array:
    """Mean over each worker's live steps, then over workers with any: `[n, W] -> []`.

    Its gradient is the average of the workers' gradients, as in synchronous A3C.
    Masked entries are selected away (not multiplied), so a NaN there cannot leak.
    """
    live = weight > 0
    total = jnp.where(live, x * weight, 0.0).sum(0)
    count = weight.sum(0)
    per_worker = total / jnp.maximum(count, 1.0)
    active = count > 0
    return jnp.where(active, per_worker, 0.0).sum() / jnp.maximum(active.sum(), 1)


def weighted_mean(x: Array, weight: Array) -> Array:
    """Mean over the live entries of `x` (any shape), weighted; 0 when none is live."""
    total = jnp.where(weight > 0, x * weight, 0.0).sum()
    return total / jnp.maximum(weight.sum(), 1.0)


def keep_if_any(new, old, weight: Array):
    """`new` where the batch has any live transition, else `old`.

    An empty batch must not touch the optimiser: a zero gradient would still decay
    RMSProp's and Adam's moment estimates.
    """
    any_live = weight.sum() > 0
    return jax.tree.map(lambda n, o: jnp.where(any_live, n, o), new, old)


def merge_moments(stats: dict, x: Array, weight: Array) -> dict:
    """Running mean and variance of observations, merged with the live rows of a batch.

    `stats` holds `mean` and `var` `[d]` and `count` `[]`; `x` is `[..., d]` with `weight`
    `[...]` (0 for masked rows). Chan et al.'s parallel update, exact for any split of the
    data into batches; a batch without live rows changes nothing.
    """
    x = x.reshape((-1, x.shape[-1]))
    w = weight.reshape((-1,))
    x = jnp.where(w[:, None] > 0, x, 0.0)  # a masked row's NaN cannot leak
    n = w.sum()
    safe_n = jnp.maximum(n, 1.0)
    batch_mean = (w[:, None] * x).sum(0) / safe_n
    batch_var = (w[:, None] * jnp.square(x - batch_mean)).sum(0) / safe_n
    count = stats["count"]
    total = count + n
    delta = batch_mean - stats["mean"]
    mean = stats["mean"] + delta * n / jnp.maximum(total, 1.0)
    m2 = (
        stats["var"] * count
        + batch_var * n
        + jnp.square(delta) * count * n / jnp.maximum(total, 1.0)
    )
    merged = {"mean": mean, "var": m2 / jnp.maximum(total, 1.0), "count": total}
    return jax.tree.map(lambda new, old: jnp.where(n > 0, new, old), merged, stats)


class Categorical:
    """Softmax policy over `n` actions; actions are int32 indices `[...]`."""

    discrete = True

    def __init__(self, n: int):
        self.n = n
        self.out_size = n
        self.model_action_size = n

    def sample(self, key: Array, out: Array) -> Array:
        return jax.random.categorical(key, out)

    def mode(self, out: Array) -> Array:
        return jnp.argmax(out, axis=-1)

    def log_prob_entropy(self, out: Array, action: Array) -> tuple[Array, Array]:
        """`log pi(action)` and the policy's entropy, `[..., n], [...] -> [...], [...]`."""
        log_probs = jax.nn.log_softmax(out)
        log_prob = jnp.take_along_axis(log_probs, action[..., None], axis=-1)[..., 0]
        entropy = -jnp.sum(jnp.exp(log_probs) * log_probs, axis=-1)
        return log_prob, entropy

    def env_action(self, action: Array) -> Array:
        return action

    def model_action(self, action: Array) -> Array:
        """What the dynamics model takes: one-hot."""
        return jax.nn.one_hot(action, self.n)


class Gaussian:
    """Diagonal Gaussian policy with the tutorial code's parametrisation: mean =
    tanh(.) * bound (centred in the bounds; unsquashed, `.` * bound, under `squash` False),
    std = softplus(.) + `min_std` (or exp of a learned log std).

    Actions are the raw samples `[..., d]`; the env and the model get them clipped to the
    bounds, and the log-probability is that of the raw sample (so PPO's ratio is exact).
    """

    discrete = False

    def __init__(
        self,
        low: tuple[float, ...],
        high: tuple[float, ...],
        min_std: float,
        log_std: bool = False,
        squash: bool = True,
    ):
        self.low = jnp.asarray(low, jnp.float32)
        self.high = jnp.asarray(high, jnp.float32)
        self.min_std = min_std
        self.log_std = log_std
        """The std's half of the output is a log std (state-independent, `log_std_init`)."""
        self.squash = squash
        """The mean is tanh-squashed into the bounds (`AgentConfig.squash_mean`)."""
        self.size = len(low)
        self.out_size = 2 * self.size
        self.net_out_size = self.size if log_std else self.out_size
        self.model_action_size = self.size

    def mean_std(self, out: Array) -> tuple[Array, Array]:
        centre, bound = (self.high + self.low) / 2, (self.high - self.low) / 2
        raw = out[..., : self.size]
        mean = centre + (jnp.tanh(raw) if self.squash else raw) * bound
        if self.log_std:
            return mean, jnp.exp(out[..., self.size :])
        std = jax.nn.softplus(out[..., self.size :]) + self.min_std
        return mean, std

    def sample(self, key: Array, out: Array) -> Array:
        mean, std = self.mean_std(out)
        return mean + std * jax.random.normal(key, mean.shape)

    def mode(self, out: Array) -> Array:
        return self.mean_std(out)[0]

    def log_prob_entropy(self, out: Array, action: Array) -> tuple[Array, Array]:
        """`log pi(action)` and the entropy, summed over action dims: `[..., 2d], [..., d]`."""
        mean, std = self.mean_std(out)
        z = (action - mean) / std
        log_prob = jnp.sum(-0.5 * jnp.square(z) - jnp.log(std) - 0.5 * jnp.log(2 * jnp.pi), -1)
        entropy = jnp.sum(0.5 + 0.5 * jnp.log(2 * jnp.pi) + jnp.log(std), axis=-1)
        return log_prob, entropy

    def env_action(self, action: Array) -> Array:
        return jnp.clip(action, self.low, self.high)

    def model_action(self, action: Array) -> Array:
        return self.env_action(action)


def make_policy(
    action_spec, min_std: float = 1e-4, log_std: bool = False, squash: bool = True
) -> Categorical | Gaussian:
    """The policy head for an env's `action_spec` (or a plain count of discrete actions)."""
    if isinstance(action_spec, int):
        return Categorical(action_spec)
    if action_spec.discrete:
        return Categorical(action_spec.size)
    return Gaussian(tuple(action_spec.low), tuple(action_spec.high), min_std, log_std, squash)


class ActorCritic:
    """The paper's actor (softmax or Gaussian policy) and critic; a learner adds its loss and
    update.

    Subclasses set `self.optimizer` and implement `update`, all with one signature.
    """

    optimizer: object

    frozen: tuple[str, ...] = ()
    """Top-level entries of the params that updates do not move (`freezing`)."""

    step_scale: tuple[tuple[str, ...], float] = ((), 1.0)
    """Top-level entries of the params whose steps are scaled, and by how much (`scaling`)."""

    def __init__(self, config: AgentConfig, obs_size: int, action_spec, workers: int = 1):
        """`action_spec`: an env's `ActionSpec`, or the number of discrete actions; `workers`:
        how many real workers play (the running returns of `normalize_reward`)."""
        self.config = config
        self.obs_size = obs_size
        self.workers = workers
        log_std = config.log_std_init is not None
        self.policy = make_policy(action_spec, config.min_std, log_std, config.squash_mean)
        mlp = lambda hidden, out, gain: MLP(
            hidden,
            out,
            config.activation,
            config.init_std,
            config.hidden_layers,
            config.init,
            gain,
        )
        out_size = getattr(self.policy, "net_out_size", self.policy.out_size)
        # under the orthogonal init, SB3's output gains: small actions, unit values
        self.actor = mlp(config.actor_hidden, out_size, 0.01)
        self.critic = mlp(config.critic_hidden, 1, 1.0)

    def init(self, key: Array) -> LearnerState:
        k_actor, k_critic = jax.random.split(key)
        dummy = jnp.zeros((1, self.obs_size))
        params = {
            "actor": self.actor.init(k_actor, dummy),
            "critic": self.critic.init(k_critic, dummy),
        }
        if getattr(self.policy, "log_std", False):
            log_std = jnp.float32(self.config.log_std_init)  # strongly typed, as after an update
            params["log_std"] = jnp.full((self.policy.size,), log_std)
        if self.config.normalize_obs:
            params["obs_norm"] = {
                "mean": jnp.zeros((self.obs_size,)),
                "var": jnp.ones((self.obs_size,)),
                "count": jnp.zeros(()),
            }
        if self.config.normalize_reward:
            params["reward_norm"] = {
                "return": jnp.zeros((self.workers,)),
                "mean": jnp.zeros((1,)),
                "var": jnp.ones((1,)),
                "count": jnp.zeros(()),
            }
        return LearnerState(params=params, opt_state=self.optimizer.init(params))

    def freezing(self, names: tuple[str, ...]) -> ActorCritic:
        """This learner with the params entries `names` frozen: each step's gradients and
        updates for them are zero, so they do not move, and a global-norm clip or PPO's KL
        guard sees only the rest. Their optimiser moments still take each step (decay, count);
        `rollout.keep_leaves` puts those back."""
        learner = copy.copy(self)
        learner.frozen = tuple(names)
        return learner

    def scaling(self, names: tuple[str, ...], scale: float) -> ActorCritic:
        """This learner with the optimiser's steps for the params entries `names` multiplied
        by `scale` (a learning rate of `scale` times their own); their gradients still enter
        the optimiser's moments whole. A scale of 1 is this learner."""
        if scale == 1.0:
            return self
        learner = copy.copy(self)
        learner.step_scale = (tuple(names), float(scale))
        return learner

    def with_epochs(self, epochs: int) -> ActorCritic:
        """This learner with `epochs` passes per update (0: its own); the A2C family makes
        one update per segment, so it is this learner (`PPO.with_epochs`)."""
        return self

    @classmethod
    def of(cls, config: Config, obs_size: int, action_spec) -> ActorCritic:
        """This learner as a run's `config` makes it (its workers, its own section)."""
        return cls(config.agent, obs_size, action_spec, config.workers)

    def apply_gradients(self, state: LearnerState, grads: dict) -> LearnerState:
        """One optimiser step from `grads`, frozen entries (`freezing`) left as they are and
        scaled ones (`scaling`) moved that much less."""
        grads = self._unfrozen(grads)
        updates, opt_state = self.optimizer.update(grads, state.opt_state, state.params)
        updates = self._unfrozen(updates)
        names, scale = self.step_scale
        if names:
            updates = {
                n: jax.tree.map(lambda u: u * scale, v) if n in names else v
                for n, v in updates.items()
            }
        return LearnerState(optax.apply_updates(state.params, updates), opt_state)

    def _unfrozen(self, tree: dict) -> dict:
        if not self.frozen:
            return tree
        return {
            n: jax.tree.map(jnp.zeros_like, v) if n in self.frozen else v for n, v in tree.items()
        }

    def per_net(self, actor, critic) -> optax.GradientTransformation:
        """One optimiser for the actor's parameters (its log std too) and one for the
        critic's; the statistics of `normalize_obs` and `normalize_reward`, which no gradient
        moves, get none."""
        transforms = {"actor": actor, "critic": critic}
        if self.config.normalize_obs or self.config.normalize_reward:
            transforms["fixed"] = optax.set_to_zero()
        owner = {"actor": "actor", "log_std": "actor", "critic": "critic"}
        labels = lambda params: {n: owner.get(n, "fixed") for n in params}
        return optax.multi_transform(transforms, labels)

    def observe(self, state: LearnerState, segment: Segment) -> LearnerState:
        """Fold a real segment `[n, W, ...]` (rows of weight 0 ignored) into the running
        statistics of `normalize_obs` (its observations) and `normalize_reward` (each
        worker's discounted return after each step); without them, `state` as it is."""
        params = dict(state.params)
        if "obs_norm" in params:
            params["obs_norm"] = merge_moments(params["obs_norm"], segment.obs, segment.weight)
        if "reward_norm" in params:
            stats = params["reward_norm"]
            gamma = self.config.gamma

            def discount(running, step):
                reward, done, weight = step
                live = weight > 0
                running = jnp.where(live, running * gamma + jnp.where(live, reward, 0.0), running)
                return jnp.where(live & done, 0.0, running), running

            steps = (segment.reward, segment.done, segment.weight)
            running, returns = jax.lax.scan(discount, stats["return"], steps)
            moments = {n: stats[n] for n in ("mean", "var", "count")}
            moments = merge_moments(moments, returns[..., None], segment.weight)
            params["reward_norm"] = {"return": running, **moments}
        return state.replace(params=params)

    def training_reward(self, params: dict, segment: Segment) -> Array:
        """The reward the learner trains on (`training_reward`), divided first by the
        running return's std under `normalize_reward` and clipped to +-`REWARD_CLIP`."""
        if "reward_norm" not in params:
            return training_reward(segment, self.config)
        stats = jax.lax.stop_gradient(params["reward_norm"])
        scaled = segment.reward / jnp.sqrt(stats["var"][0] + 1e-8)
        segment = segment.replace(reward=jnp.clip(scaled, -REWARD_CLIP, REWARD_CLIP))
        return training_reward(segment, self.config)

    def normalized(self, params: dict, obs: Array) -> Array:
        """What actor and critic see: `obs`, standardised under `normalize_obs`."""
        if "obs_norm" not in params:
            return obs
        stats = jax.lax.stop_gradient(params["obs_norm"])
        z = (obs - stats["mean"]) / jnp.sqrt(stats["var"] + 1e-8)
        return jnp.clip(z, -self.config.obs_clip, self.config.obs_clip)

    def logits(self, params: dict, obs: Array) -> Array:
        """The actor's raw output: logits (discrete) or mean and std pre-activations (the
        learned log std broadcast beside the mean, under `log_std_init`)."""
        out = self.actor.apply(params["actor"], self.normalized(params, obs))
        if "log_std" not in params:
            return out
        return jnp.concatenate([out, jnp.broadcast_to(params["log_std"], out.shape)], -1)

    def value(self, params: dict, obs: Array) -> Array:
        return self.critic.apply(params["critic"], self.normalized(params, obs))[..., 0]

    def act(self, params: dict, key: Array, obs: Array) -> Array:
        """Sample from the policy, `[W, obs] -> [W]` (discrete) or `[W, d]` (continuous)."""
        return self.policy.sample(key, self.logits(params, obs))

    def behave(self, state: LearnerState, key: Array, obs: Array) -> Array:
        """The action in the real env: `act`'s (a learner that warms up otherwise reads its
        whole state)."""
        return self.act(state.params, key, obs)

    def greedy(self, params: dict, obs: Array) -> Array:
        """The deterministic action: argmax or the mean, as the env takes it."""
        return self.policy.env_action(self.policy.mode(self.logits(params, obs)))

    def env_action(self, action: Array) -> Array:
        return self.policy.env_action(action)

    def log_prob_entropy(self, params: dict, obs: Array, action: Array) -> tuple[Array, Array]:
        return self.policy.log_prob_entropy(self.logits(params, obs), action)

    def update(
        self, state: LearnerState, segment: Segment, key: Array | None = None
    ) -> tuple[LearnerState, dict]:
        """Learn from one segment `[W, n]` of masked steps: `(new state, losses)`; a fully
        masked segment leaves `state` unchanged. `key`: for learners that draw (PPO's
        minibatch shuffle); a deterministic one ignores it."""
        raise NotImplementedError
