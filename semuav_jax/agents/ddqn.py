"""The Double DQN at the BS (MODEL.md sections 5-6), trained in one compiled program.

PureJaxRL style: ``make_train(config, params)`` returns pure functions; the whole training run
is ``lax.scan`` over *chunks*, and each chunk is ``steps_per_chunk`` vmapped environment steps,
each followed by ``updates_per_step`` gradient updates on a replay minibatch. The replay memory
is a ring buffer of device arrays inside the compiled program. The schedule is fixed (no
data-dependent branches): a warm-up phase fills the memory with random actions, epsilon decays
linearly with the step counter, and the target network is synced every ``target_period``
chunks by a ``jnp.where`` blend (a select, cheap for ~40 k parameters).

Network and optimiser follow the paper: MLP 128-128-64 with ReLU, one Q-value per action
(MODEL.md section 6), Adam, replay memory of 50 000 transitions. Unless ``shield_margin`` is
None, the BS's return-home shield (``agents/shield.py``) filters every action, exploratory ones
included, and the memory stores the action sent. The default learning rate is
2.5e-4 rather than the paper's 5e-5, which learns too slowly for a 10-minute CPU budget
(docs/ddqn.md).
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp
import optax
from flax import struct

from semuav_jax.actions import action_to_accel
from semuav_jax.agents.shield import shield
from semuav_jax.env import reset_state, transition
from semuav_jax.metrics import episode_metrics
from semuav_jax.observation import DEVICE_FEATURES, GLOBAL_FEATURES, obs_size, observation
from semuav_jax.params import EnvParams


@dataclasses.dataclass(frozen=True)
class DDQNConfig:
    """Hyperparameters (static). ``total_steps`` counts environment steps summed over envs."""

    num_envs: int = 32
    total_steps: int = 3_000_000
    steps_per_chunk: int = 250
    updates_per_step: int = 1
    batch_size: int = 128
    buffer_size: int = 50_000
    learning_starts: int = 10_000
    lr: float = 2.5e-4
    gamma: float = 0.999
    eps_start: float = 1.0
    eps_end: float = 0.02
    eps_decay_frac: float = 0.5
    target_period: int = 4
    reward_scale: float = 0.01
    max_grad_norm: float = 10.0
    hidden: tuple = (128, 128, 64)
    sorted_devices: bool = True
    shield_margin: float | None = 2.0

    def __post_init__(self):
        ints = ("num_envs", "total_steps", "steps_per_chunk", "updates_per_step", "batch_size",
                "buffer_size", "target_period")
        for name in ints:
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be a positive integer, got {getattr(self, name)}")
        if self.learning_starts < self.batch_size:
            raise ValueError(f"learning_starts ({self.learning_starts}) must be >= batch_size ({self.batch_size})")
        if self.learning_starts > self.buffer_size:
            raise ValueError(f"learning_starts ({self.learning_starts}) must be <= buffer_size ({self.buffer_size})")
        if self.buffer_size < self.num_envs:
            raise ValueError(f"buffer_size ({self.buffer_size}) must be >= num_envs ({self.num_envs})")
        if not 0.0 <= self.eps_end <= self.eps_start <= 1.0:
            raise ValueError(f"need 0 <= eps_end <= eps_start <= 1, got {self.eps_end}, {self.eps_start}")
        if not 0.0 < self.eps_decay_frac <= 1.0:
            raise ValueError(f"eps_decay_frac must be in (0, 1], got {self.eps_decay_frac}")
        if not 0.0 <= self.gamma <= 1.0:
            raise ValueError(f"gamma must be in [0, 1], got {self.gamma}")
        if self.shield_margin is not None and not self.shield_margin >= 0:
            raise ValueError(f"shield_margin must be >= 0 seconds or None (no shield), got {self.shield_margin}")
        if self.lr <= 0 or self.reward_scale <= 0:
            raise ValueError("lr and reward_scale must be > 0")
        if self.num_chunks < 1:
            raise ValueError(
                f"total_steps ({self.total_steps}) is less than one chunk "
                f"(num_envs * steps_per_chunk = {self.num_envs * self.steps_per_chunk})"
            )

    @property
    def warmup_steps(self) -> int:
        """Vmapped env steps of the random warm-up that fills the memory to ``learning_starts``."""
        return -(-self.learning_starts // self.num_envs)

    @property
    def num_chunks(self) -> int:
        return self.total_steps // (self.num_envs * self.steps_per_chunk)

    def to_dict(self) -> dict:
        return {**dataclasses.asdict(self), "hidden": list(self.hidden)}

    @classmethod
    def from_dict(cls, d: dict) -> "DDQNConfig":
        return cls(**{**d, "hidden": tuple(d["hidden"])})


NEAR_GAIN = 20.0  # tanh(20 x): resolves tens of metres in area-normalized offsets


def agent_features(obs):
    """The Q-network's input: the observation (MODEL.md section 5) made permutation-invariant.

    Device blocks are sorted nearest first (the device index carries no meaning on random
    layouts), and every relative offset (devices and goal) gets a companion ``tanh(20 x)`` that
    resolves the ~32 m communication radius, which the area normalization squeezes to ~0.03.
    A fixed, parameter-free transform; works on one observation or a batch.
    """
    glob, dev = obs[..., :GLOBAL_FEATURES], obs[..., GLOBAL_FEATURES:]
    dev = dev.reshape(dev.shape[:-1] + (-1, DEVICE_FEATURES))
    order = jnp.argsort(jnp.sum(dev[..., :2] ** 2, axis=-1), axis=-1)
    dev = jnp.take_along_axis(dev, order[..., None], axis=-2)
    dev = jnp.concatenate([dev, jnp.tanh(NEAR_GAIN * dev[..., :2])], axis=-1)
    near_goal = jnp.tanh(NEAR_GAIN * glob[..., GLOBAL_FEATURES - 2:])
    return jnp.concatenate([glob, near_goal, dev.reshape(dev.shape[:-2] + (-1,))], axis=-1)


class QNetwork(nn.Module):
    """MLP 128-128-64 with ReLU and one linear output per action (the paper's Q-network).

    With ``sorted_devices`` the observation first goes through :func:`agent_features`.
    """

    num_actions: int
    hidden: tuple = (128, 128, 64)
    sorted_devices: bool = True

    @nn.compact
    def __call__(self, x):
        if self.sorted_devices:
            x = agent_features(x)
        for h in self.hidden:
            x = nn.relu(nn.Dense(h)(x))
        return nn.Dense(self.num_actions)(x)


# ---------------------------------------------------------------- replay memory (ring buffer)


class Transition(NamedTuple):
    obs: jax.Array
    action: jax.Array
    reward: jax.Array
    next_obs: jax.Array
    done: jax.Array


@struct.dataclass
class Replay:
    """Ring buffer of ``capacity`` transitions; ``pos`` is the next write slot, ``size`` the fill."""

    data: Transition
    pos: jax.Array
    size: jax.Array

    @property
    def capacity(self) -> int:
        return self.data.done.shape[0]


def replay_init(capacity: int, obs_dim: int) -> Replay:
    data = Transition(
        obs=jnp.zeros((capacity, obs_dim), jnp.float32),
        action=jnp.zeros((capacity,), jnp.int32),
        reward=jnp.zeros((capacity,), jnp.float32),
        next_obs=jnp.zeros((capacity, obs_dim), jnp.float32),
        done=jnp.zeros((capacity,), jnp.float32),
    )
    return Replay(data=data, pos=jnp.zeros((), jnp.int32), size=jnp.zeros((), jnp.int32))


def replay_add(buf: Replay, batch: Transition) -> Replay:
    """Write a batch of B transitions at pos, pos+1, ... (mod capacity), overwriting the oldest."""
    n = batch.done.shape[0]
    idx = (buf.pos + jnp.arange(n)) % buf.capacity
    data = jax.tree.map(lambda d, b: d.at[idx].set(b.astype(d.dtype)), buf.data, batch)
    return Replay(data=data, pos=(buf.pos + n) % buf.capacity, size=jnp.minimum(buf.size + n, buf.capacity))


def replay_sample(buf: Replay, key, batch_size: int) -> Transition:
    """Uniform sample (with replacement) among the ``size`` stored transitions."""
    idx = jax.random.randint(key, (batch_size,), 0, jnp.maximum(buf.size, 1))
    return jax.tree.map(lambda d: d[idx], buf.data)


# ---------------------------------------------------------------- double-Q learning


def double_q_target(q_next_online, q_next_target, reward, done, gamma):
    """y = r + gamma (1 - done) Q_target(s', argmax_a Q_online(s', a)) (van Hasselt et al. 2016)."""
    a_star = jnp.argmax(q_next_online, axis=-1)
    q_eval = jnp.take_along_axis(q_next_target, a_star[..., None], axis=-1)[..., 0]
    return reward + gamma * (1.0 - done) * q_eval


def epsilon(step, config: DDQNConfig):
    """Linear decay from eps_start to eps_end over the first eps_decay_frac of the learning steps."""
    n = max(1, int(config.eps_decay_frac * config.num_chunks * config.steps_per_chunk))
    frac = jnp.clip(step / n, 0.0, 1.0)
    return config.eps_start + frac * (config.eps_end - config.eps_start)


@struct.dataclass
class TrainState:
    """Everything the compiled training loop carries (one agent); checkpointable as a pytree."""

    params: Any
    target_params: Any
    opt_state: Any
    replay: Replay
    env_state: Any
    obs: jax.Array
    key: jax.Array
    step: jax.Array  # vmapped env steps taken after warm-up
    updates: jax.Array  # gradient updates
    chunk: jax.Array  # chunks done


class Trainer(NamedTuple):
    """The pure functions of one training run (see :func:`make_train`)."""

    config: DDQNConfig
    network: QNetwork
    init: Any  # key -> TrainState (warm-up included)
    run: Any  # (TrainState, n_chunks static) -> (TrainState, per-chunk metrics)
    train: Any  # key -> (TrainState, per-chunk metrics), the whole run


def make_train(config: DDQNConfig, env_params: EnvParams) -> Trainer:
    """Build the pure training functions for one agent; ``jax.vmap(trainer.train)(keys)`` trains seeds."""
    network = QNetwork(env_params.num_actions, tuple(config.hidden), config.sorted_devices)
    tx = optax.chain(optax.clip_by_global_norm(config.max_grad_norm), optax.adam(config.lr))
    n_act = env_params.num_actions
    E = config.num_envs

    def env_step(key, state, action):
        """Step every env; reset finished ones. Returns next obs (pre-reset), state, reward, done, metrics."""
        k_step, k_reset = jax.random.split(key)
        accel = action_to_accel(action, env_params)
        new, rew = jax.vmap(transition, (0, 0, 0, None))(jax.random.split(k_step, E), state, accel, env_params)
        next_obs = jax.vmap(observation, (0, None))(new, env_params)
        met = jax.vmap(episode_metrics, (0, None))(new, env_params)
        fresh = jax.vmap(reset_state, (0, None))(jax.random.split(k_reset, E), env_params)
        done = new.done
        state = jax.tree.map(lambda f, s: jnp.where(done.reshape((-1,) + (1,) * (s.ndim - 1)), f, s), fresh, new)
        obs = jax.vmap(observation, (0, None))(state, env_params)
        return obs, next_obs, state, rew, done, met

    def loss_fn(params, target_params, batch):
        q = network.apply(params, batch.obs)
        q_a = jnp.take_along_axis(q, batch.action[:, None], axis=-1)[:, 0]
        q_next_online = network.apply(params, batch.next_obs)
        q_next_target = network.apply(target_params, batch.next_obs)
        y = double_q_target(q_next_online, q_next_target, batch.reward, batch.done, config.gamma)
        return jnp.mean(optax.huber_loss(q_a, jax.lax.stop_gradient(y)))

    def update(ts: TrainState, key):
        batch = replay_sample(ts.replay, key, config.batch_size)
        loss, grads = jax.value_and_grad(loss_fn)(ts.params, ts.target_params, batch)
        upd, opt_state = tx.update(grads, ts.opt_state, ts.params)
        return ts.replace(params=optax.apply_updates(ts.params, upd), opt_state=opt_state, updates=ts.updates + 1), loss

    def act_and_store(ts: TrainState, key, eps):
        k_eps, k_rand, k_env = jax.random.split(key, 3)
        greedy = jnp.argmax(network.apply(ts.params, ts.obs), axis=-1)
        rand = jax.random.randint(k_rand, (E,), 0, n_act)
        action = jnp.where(jax.random.uniform(k_eps, (E,)) < eps, rand, greedy)
        action = jax.vmap(shield, (0, 0, None, None))(action, ts.env_state, env_params, config.shield_margin)
        obs, next_obs, state, rew, done, met = env_step(k_env, ts.env_state, action)
        tr = Transition(ts.obs, action, rew * config.reward_scale, next_obs, done.astype(jnp.float32))
        ts = ts.replace(replay=replay_add(ts.replay, tr), env_state=state, obs=obs)
        return ts, (done, met)

    def init(key) -> TrainState:
        k_net, k_env, k_warm, k_run = jax.random.split(key, 4)
        dummy = jnp.zeros((obs_size(env_params),), jnp.float32)
        params = network.init(k_net, dummy)
        env_state = jax.vmap(reset_state, (0, None))(jax.random.split(k_env, E), env_params)
        ts = TrainState(
            params=params,
            target_params=params,
            opt_state=tx.init(params),
            replay=replay_init(config.buffer_size, obs_size(env_params)),
            env_state=env_state,
            obs=jax.vmap(observation, (0, None))(env_state, env_params),
            key=k_run,
            step=jnp.zeros((), jnp.int32),
            updates=jnp.zeros((), jnp.int32),
            chunk=jnp.zeros((), jnp.int32),
        )

        def warm(ts, k):
            ts, _ = act_and_store(ts, k, 1.0)
            return ts, None

        ts, _ = jax.lax.scan(warm, ts, jax.random.split(k_warm, config.warmup_steps))
        return ts

    def one_step(ts: TrainState, _):
        key, k_act, k_upd = jax.random.split(ts.key, 3)
        ts = ts.replace(key=key)
        ts, (done, met) = act_and_store(ts, k_act, epsilon(ts.step, config))
        ts, losses = jax.lax.scan(update, ts, jax.random.split(k_upd, config.updates_per_step))
        ts = ts.replace(step=ts.step + 1)
        d = done.astype(jnp.float32)
        stats = {k: jnp.sum(d * met[k].astype(jnp.float32)) for k in ("mean_psnr", "return", "arrived", "coverage")}
        return ts, {"episodes": jnp.sum(d), "loss": jnp.mean(losses), **stats}

    def one_chunk(ts: TrainState, _):
        eps = epsilon(ts.step, config)
        ts, s = jax.lax.scan(one_step, ts, None, config.steps_per_chunk)
        chunk = ts.chunk + 1
        sync = chunk % config.target_period == 0
        target = jax.tree.map(lambda p, t: jnp.where(sync, p, t), ts.params, ts.target_params)
        ts = ts.replace(target_params=target, chunk=chunk)
        n = jnp.maximum(s["episodes"].sum(), 1.0)
        out = {
            "env_steps": (ts.step + config.warmup_steps) * E,
            "epsilon": eps,
            "episodes": s["episodes"].sum(),
            "loss": s["loss"].mean(),
            **{k: s[k].sum() / n for k in ("mean_psnr", "return", "arrived", "coverage")},
        }
        return ts, out

    def run(ts: TrainState, n_chunks: int):
        return jax.lax.scan(one_chunk, ts, None, n_chunks)

    def train(key):
        return run(init(key), config.num_chunks)

    return Trainer(config=config, network=network, init=init, run=run, train=train)

