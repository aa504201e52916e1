"""The Double DQN at the BS (MODEL.md sections 5-6), trained in one compiled program.

PureJaxRL style: ``make_train(config, params)`` returns pure functions; the whole training run
is ``lax.scan`` over *chunks*, and each chunk is ``steps_per_chunk`` vmapped steps of
:class:`AgentEnv` (``SemUAVEnv`` with gymnax's auto-reset, seen through the agent's input),
each followed by ``updates_per_step`` gradient updates on a replay minibatch. The replay memory
is a ring buffer of device arrays inside the compiled program (any buffer with flashbax's
``init``/``add``/``sample`` can replace it). The schedule is fixed (no data-dependent
branches): a warm-up phase fills the memory with random actions, epsilon decays linearly
(``optax.linear_schedule``) and the target network is synced every ``target_period`` chunks
(``optax.periodic_update``).

Network and optimiser follow the paper: MLP 128-128-64 with ReLU, one Q-value per action
(MODEL.md section 6), Adam, replay memory of 50 000 transitions. Unless ``shield_margin`` is
None, the BS's return-home shield (``agents/shield.py``) filters every action, exploratory ones
included, and the memory stores the action sent. The default learning rate is
2.5e-4 rather than the paper's 5e-5, which learns too slowly for a 10-minute CPU budget
(docs/ddqn.md).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp
import optax
from flax import struct
from gymnax.environments import spaces

from semuav_jax import actions as action_modes
from semuav_jax.actions import ACTION_MODES
from semuav_jax.agents.features import table_features, waypoint_features
from semuav_jax.agents.shield import shield, waypoint_shield
from semuav_jax.env import SemUAVEnv, reset_state
from semuav_jax.metrics import episode_metrics
from semuav_jax.observation import observation
from semuav_jax.params import EnvParams


def _f(default, help: str):
    """A config field with its command-line help (``train.py`` derives its options from these)."""
    return dataclasses.field(default=default, metadata={"help": help})


@dataclasses.dataclass(frozen=True)
class DDQNConfig:
    """Hyperparameters (static). ``total_steps`` counts environment steps summed over envs."""

    num_envs: int = _f(64, "parallel environments per agent")
    total_steps: int = _f(16_000_000, "environment steps per agent, summed over its envs")
    steps_per_chunk: int = _f(250, "vmapped env steps per compiled chunk (target sync and metrics per chunk)")
    updates_per_step: int = _f(1, "gradient updates after each vmapped env step")
    batch_size: int = _f(256, "replay minibatch")
    buffer_size: int = _f(50_000, "replay memory, transitions")
    learning_starts: int = _f(10_000, "random transitions stored before learning")
    lr: float = _f(2.5e-4, "Adam learning rate")
    lr_end: float = _f(0.1, "learning rate at the end of training as a share of lr (cosine decay); 1: constant")
    gamma: float = _f(0.99, "discount per slot")
    eps_start: float = _f(1.0, "initial exploration rate")
    eps_end: float = _f(0.02, "final exploration rate")
    eps_decay_frac: float = _f(0.5, "share of training over which epsilon decays linearly")
    target_period: int = _f(4, "chunks between target-network syncs")
    n_step: int = _f(10, "steps summed in each return before bootstrapping")
    reward_scale: float = _f(0.01, "multiplies every reward before learning")
    max_grad_norm: float = _f(10.0, "global gradient-norm clip")
    hidden: tuple = _f((128, 128, 64), "hidden layer widths of the Q-network MLP")
    dueling: bool = _f(False, "dueling head: Q = V + A - mean(A) (Wang et al. 2016) instead of one linear layer")
    sorted_devices: bool = _f(True, "table actions: sort device blocks nearest first and add tanh offsets")
    shield_margin: float | None = _f(2.0, "seconds of slack of the BS's return-home shield; none: no shield")
    actions: str = _f(
        "waypoint", "waypoint (eq. 6.2: device, speed or hover, home) or table (the paper's 9 accelerations)"
    )
    bandwidth_range: tuple | None = _f(
        (4e3, 45e3),
        "(lo, hi) Hz: the envs train at bandwidths evenly spaced in the range "
        "(one agent for every B); none: the scenario's B",
    )

    def __post_init__(self):
        for name in ("hidden", "bandwidth_range"):  # lists (from JSON or the command line) become tuples
            if isinstance(getattr(self, name), list):
                object.__setattr__(self, name, tuple(getattr(self, name)))
        ints = (
            "num_envs",
            "total_steps",
            "steps_per_chunk",
            "updates_per_step",
            "batch_size",
            "buffer_size",
            "target_period",
            "n_step",
        )
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
        if self.actions not in ACTION_MODES:
            raise ValueError(f"actions must be one of {ACTION_MODES}, got {self.actions!r}")
        if self.bandwidth_range is not None:
            lo, hi = self.bandwidth_range
            if not 0 < lo <= hi < float("inf"):
                raise ValueError(
                    f"bandwidth_range must be (lo, hi) with 0 < lo <= hi, finite, got {self.bandwidth_range}"
                )
        if not self.hidden or not all(isinstance(h, int) and h >= 1 for h in self.hidden):
            raise ValueError(f"hidden must be one or more positive layer widths, got {self.hidden}")
        if not 0.0 < self.lr_end <= 1.0:
            raise ValueError(f"lr_end must be in (0, 1], got {self.lr_end}")
        for name in ("lr", "reward_scale", "max_grad_norm"):
            if not 0 < getattr(self, name) < float("inf"):  # NaN fails too
                raise ValueError(f"{name} must be finite and > 0, got {getattr(self, name)}")
        if self.shield_margin is not None and self.shield_margin == float("inf"):
            raise ValueError("shield_margin must be finite (none: no shield)")
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
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> DDQNConfig:
        return cls(**d)


PRESETS = {
    "default": {},
    # the paper's configuration (MODEL.md section 6, PAPER_CLAIMS.md): paper reward with the shield, lr 5e-5,
    # MLP 128-128-64, the 9 accelerations, the raw observation, 1-step targets, trained at one bandwidth
    "paper": {
        "reward_mode": "paper",
        "r_g": 500.0,
        "actions": "table",
        "sorted_devices": False,
        "lr": 5e-5,
        "hidden": (128, 128, 64),
        "n_step": 1,
        "gamma": 0.999,
        "bandwidth_range": None,
        "dueling": False,
        "lr_end": 1.0,
    },
}  # DDQNConfig overrides, plus the scenario's reward_mode and arrival reward r_g


def preset_config(name: str, **overrides) -> DDQNConfig:
    """The DDQNConfig of preset ``name`` with ``overrides``."""
    fields = {f.name for f in dataclasses.fields(DDQNConfig)}
    return DDQNConfig(**{**{k: v for k, v in PRESETS[name].items() if k in fields}, **overrides})


def agent_input(state, params: EnvParams, config: DDQNConfig):
    """The Q-network's input for one ``EnvState`` (``agents/features.py``)."""
    if config.actions == "waypoint":
        return waypoint_features(state, params)
    obs = observation(state, params)
    return table_features(obs) if config.sorted_devices else obs


def input_size(params: EnvParams, config: DDQNConfig) -> int:
    state = jax.eval_shape(reset_state, jax.random.key(0), params)
    return int(jax.eval_shape(lambda s: agent_input(s, params, config), state).shape[0])


def num_actions(params: EnvParams, config: DDQNConfig) -> int:
    return action_modes.num_actions(config.actions, params)


def shielded(action, state, params: EnvParams, config: DDQNConfig):
    """The action the BS sends for the agent's ``action``: through its shield (``agents/shield.py``)."""
    if config.actions == "waypoint":
        return waypoint_shield(action, state, params, config.shield_margin)
    return shield(action, state, params, config.shield_margin)


def command(action, state, params: EnvParams, config: DDQNConfig):
    """What the BS sends for the agent's ``action``: (the action after the shield, its acceleration)."""
    sent = shielded(action, state, params, config)
    return sent, action_modes.to_accel(config.actions, sent, state, params)


class AgentEnv(SemUAVEnv):
    """``SemUAVEnv`` in the agent's action mode, observed through the agent's input
    (:func:`agent_input`); ``info["metrics"]`` holds the episode metrics (MODEL.md section 8) of
    the state before any reset, so training can log finished episodes."""

    def __init__(self, params: EnvParams, config: DDQNConfig):
        super().__init__(params, config.actions)
        self.config = config

    def get_obs(self, state, params: EnvParams | None = None, key=None):
        return agent_input(state, params or self.default_params, self.config)

    def observation_space(self, params: EnvParams | None = None) -> spaces.Box:
        n = input_size(params or self.default_params, self.config)
        return spaces.Box(-jnp.inf, jnp.inf, (n,), jnp.float32)

    def step_env(self, key, state, action, params: EnvParams):
        obs, new, rew, done, info = super().step_env(key, state, action, params)
        return obs, new, rew, done, info | {"metrics": episode_metrics(new, params)}


def train_bandwidths(config: DDQNConfig, params: EnvParams):
    """(num_envs,) bandwidth of each training env: evenly spaced over ``bandwidth_range``, or params.B."""
    if config.bandwidth_range is None:
        return jnp.full((config.num_envs,), params.B, jnp.float32)
    lo, hi = config.bandwidth_range
    return jnp.linspace(lo, hi, config.num_envs).astype(jnp.float32)


class QNetwork(nn.Module):
    """MLP with ReLU and one linear output per action (the paper's: 128-128-64); with ``dueling``,
    a value and an advantage head, Q = V + A - mean(A)."""

    num_actions: int
    hidden: tuple = (128, 128, 64)
    dueling: bool = False

    @nn.compact
    def __call__(self, x):
        for h in self.hidden:
            x = nn.relu(nn.Dense(h)(x))
        if not self.dueling:
            return nn.Dense(self.num_actions)(x)
        adv = nn.Dense(self.num_actions, name="advantage")(x)
        return nn.Dense(1, name="value")(x) + adv - jnp.mean(adv, axis=-1, keepdims=True)


def q_network(params: EnvParams, config: DDQNConfig) -> QNetwork:
    """The Q-network of ``config`` for ``params``' action count."""
    return QNetwork(num_actions(params, config), tuple(config.hidden), config.dueling)


# ---------------------------------------------------------------- replay memory (ring buffer)


class Transition(NamedTuple):
    """One stored (n-step) transition: y = reward + discount (1 - done) max-Q(next_obs)."""

    obs: jax.Array
    action: jax.Array
    reward: jax.Array
    next_obs: jax.Array
    done: jax.Array
    discount: jax.Array


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
        discount=jnp.zeros((capacity,), jnp.float32),
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


class ReplayBuffer(NamedTuple):
    """A replay memory as pure functions, with flashbax's signatures: ``init(example Transition)``,
    ``add(state, batch of Transitions)``, ``sample(state, key)`` -> an object whose ``experience``
    is a batch of Transitions (``flashbax.make_item_buffer(..., add_batches=True)`` fits)."""

    init: Callable
    add: Callable
    sample: Callable


class Sample(NamedTuple):
    experience: Transition


def ring_buffer(capacity: int, batch_size: int) -> ReplayBuffer:
    """The default memory: :class:`Replay`, uniform sampling with replacement."""
    return ReplayBuffer(
        init=lambda example: replay_init(capacity, example.obs.shape[-1]),
        add=replay_add,
        sample=lambda buf, key: Sample(replay_sample(buf, key, batch_size)),
    )


# ---------------------------------------------------------------- double-Q learning


def double_q_target(q_next_online, q_next_target, reward, done, gamma):
    """y = r + gamma (1 - done) Q_target(s', argmax_a Q_online(s', a)) (van Hasselt et al. 2016)."""
    a_star = jnp.argmax(q_next_online, axis=-1)
    q_eval = jnp.take_along_axis(q_next_target, a_star[..., None], axis=-1)[..., 0]
    return reward + gamma * (1.0 - done) * q_eval


def n_step_transition(window: Transition, gamma: float) -> Transition:
    """The n-step transition of the oldest entry of ``window`` (n one-step transitions, oldest first,
    leading axis n): rewards summed with gamma^k up to and including the first ``done``, bootstrapped
    from the next observation there with discount gamma^m, m the number of steps summed."""
    n = window.done.shape[0]
    alive = jnp.cumprod(jnp.concatenate([jnp.ones_like(window.done[:1]), 1.0 - window.done[:-1]]), axis=0)
    powers = gamma ** jnp.arange(n, dtype=jnp.float32).reshape((n,) + (1,) * (window.done.ndim - 1))
    steps = jnp.sum(alive, axis=0).astype(jnp.int32)
    last = jnp.take_along_axis(window.next_obs, (steps - 1)[None, ..., None], axis=0)[0]
    return Transition(
        obs=window.obs[0],
        action=window.action[0],
        reward=jnp.sum(powers * alive * window.reward, axis=0),
        next_obs=last,
        done=1.0 - jnp.prod(1.0 - window.done, axis=0),
        discount=gamma ** steps.astype(jnp.float32),
    )


def epsilon(step, config: DDQNConfig):
    """Linear decay from eps_start to eps_end over the first eps_decay_frac of the learning steps."""
    n = max(1, int(config.eps_decay_frac * config.num_chunks * config.steps_per_chunk))
    return optax.linear_schedule(config.eps_start, config.eps_end, n)(step)


@struct.dataclass
class TrainState:
    """Everything the compiled training loop carries (one agent); checkpointable as a pytree."""

    params: Any
    target_params: Any
    opt_state: Any
    replay: Any  # the replay buffer's state (:class:`Replay` by default)
    window: Transition  # the last n_step one-step transitions of every env (leading axis n_step)
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


def make_train(config: DDQNConfig, env_params: EnvParams, progress=None, buffer: ReplayBuffer | None = None) -> Trainer:
    """Build the pure training functions for one agent; ``jax.vmap(trainer.train)(keys)`` trains seeds.

    ``progress`` (optional, host) is called with the number of chunks done after every chunk, from
    inside the compiled loop (``jax.debug.callback``; once per seed when vmapped), so a progress bar
    can move within a long compiled run. ``buffer`` replaces the replay memory (default
    :func:`ring_buffer`)."""
    network = q_network(env_params, config)
    updates = config.num_chunks * config.steps_per_chunk * config.updates_per_step
    lr = config.lr if config.lr_end == 1.0 else optax.cosine_decay_schedule(config.lr, updates, config.lr_end)
    tx = optax.chain(optax.clip_by_global_norm(config.max_grad_norm), optax.adam(lr))
    buffer = ring_buffer(config.buffer_size, config.batch_size) if buffer is None else buffer
    n_act = num_actions(env_params, config)
    n_in = input_size(env_params, config)
    E = config.num_envs
    env = AgentEnv(env_params, config)
    # every env has its own bandwidth (traced): one vmap over envs and their parameters
    env_batch = env_params.replace(B=train_bandwidths(config, env_params))
    axes = jax.tree.map(lambda _: None, env_params).replace(B=0)
    env_reset = jax.vmap(env.reset, (0, axes))
    env_step = jax.vmap(env.step, (0, 0, 0, axes))

    def loss_fn(params, target_params, batch):
        q = network.apply(params, batch.obs)
        q_a = jnp.take_along_axis(q, batch.action[:, None], axis=-1)[:, 0]
        q_next_online = network.apply(params, batch.next_obs)
        q_next_target = network.apply(target_params, batch.next_obs)
        y = double_q_target(q_next_online, q_next_target, batch.reward, batch.done, batch.discount)
        return jnp.mean(optax.huber_loss(q_a, jax.lax.stop_gradient(y)))

    def update(ts: TrainState, key):
        batch = buffer.sample(ts.replay, key).experience
        loss, grads = jax.value_and_grad(loss_fn)(ts.params, ts.target_params, batch)
        upd, opt_state = tx.update(grads, ts.opt_state, ts.params)
        return ts.replace(params=optax.apply_updates(ts.params, upd), opt_state=opt_state, updates=ts.updates + 1), loss

    def act(ts: TrainState, key, eps):
        """One vmapped env step; the transition enters the n-step window (not yet the memory)."""
        k_eps, k_rand, k_env = jax.random.split(key, 3)
        greedy = jnp.argmax(network.apply(ts.params, ts.obs), axis=-1)
        rand = jax.random.randint(k_rand, (E,), 0, n_act)
        chosen = jnp.where(jax.random.uniform(k_eps, (E,)) < eps, rand, greedy)
        action = jax.vmap(shielded, (0, 0, axes, None))(chosen, ts.env_state, env_batch, config)
        obs, state, rew, done, _, info = env_step(jax.random.split(k_env, E), ts.env_state, action, env_batch)
        met = info["metrics"]
        one = Transition(
            ts.obs,
            action,
            rew * config.reward_scale,
            info["final_observation"],
            done.astype(jnp.float32),
            jnp.full((E,), config.gamma, jnp.float32),
        )
        window = jax.tree.map(lambda w, x: jnp.concatenate([w[1:], x[None]]), ts.window, one)
        ts = ts.replace(window=window, env_state=state, obs=obs)
        return ts, (done, met, jnp.mean((action != chosen).astype(jnp.float32)))

    def act_and_store(ts: TrainState, key, eps):
        ts, out = act(ts, key, eps)
        return ts.replace(replay=buffer.add(ts.replay, n_step_transition(ts.window, config.gamma))), out

    def init(key) -> TrainState:
        k_net, k_env, k_warm, k_run = jax.random.split(key, 4)
        params = network.init(k_net, jnp.zeros((n_in,), jnp.float32))
        obs, env_state = env_reset(jax.random.split(k_env, E), env_batch)
        empty = replay_init(E, n_in).data
        ts = TrainState(
            params=params,
            target_params=params,
            opt_state=tx.init(params),
            replay=buffer.init(jax.tree.map(lambda x: x[0], empty)),
            window=jax.tree.map(lambda x: jnp.zeros((config.n_step,) + x.shape, x.dtype), empty),
            env_state=env_state,
            obs=obs,
            key=k_run,
            step=jnp.zeros((), jnp.int32),
            updates=jnp.zeros((), jnp.int32),
            chunk=jnp.zeros((), jnp.int32),
        )

        def warm(store):
            def step(ts, k):
                ts, _ = (act_and_store if store else act)(ts, k, 1.0)
                return ts, None

            return step

        k_fill, k_warm = jax.random.split(k_warm)
        ts, _ = jax.lax.scan(warm(False), ts, jax.random.split(k_fill, config.n_step - 1))  # fill the window
        ts, _ = jax.lax.scan(warm(True), ts, jax.random.split(k_warm, config.warmup_steps))
        return ts

    def one_step(ts: TrainState, _):
        key, k_act, k_upd = jax.random.split(ts.key, 3)
        ts = ts.replace(key=key)
        ts, (done, met, shielded) = act_and_store(ts, k_act, epsilon(ts.step, config))
        ts, losses = jax.lax.scan(update, ts, jax.random.split(k_upd, config.updates_per_step))
        ts = ts.replace(step=ts.step + 1)
        d = done.astype(jnp.float32)
        stats = {k: jnp.sum(d * met[k].astype(jnp.float32)) for k in ("mean_psnr", "return", "arrived", "coverage")}
        return ts, {"episodes": jnp.sum(d), "loss": jnp.mean(losses), "shield_share": shielded, **stats}

    def one_chunk(ts: TrainState, _):
        eps = epsilon(ts.step, config)
        ts, s = jax.lax.scan(one_step, ts, None, config.steps_per_chunk)
        chunk = ts.chunk + 1
        ts = ts.replace(
            target_params=optax.periodic_update(ts.params, ts.target_params, chunk, config.target_period), chunk=chunk
        )
        if progress is not None:
            jax.debug.callback(progress, chunk)
        n = jnp.maximum(s["episodes"].sum(), 1.0)
        out = {
            "env_steps": (ts.step + config.warmup_steps) * E,
            "epsilon": eps,
            "episodes": s["episodes"].sum(),
            "loss": s["loss"].mean(),
            "shield_share": s["shield_share"].mean(),
            **{k: s[k].sum() / n for k in ("mean_psnr", "return", "arrived", "coverage")},
        }
        return ts, out

    def run(ts: TrainState, n_chunks: int):
        return jax.lax.scan(one_chunk, ts, None, n_chunks)

    def train(key):
        return run(init(key), config.num_chunks)

    return Trainer(config=config, network=network, init=init, run=run, train=train)
