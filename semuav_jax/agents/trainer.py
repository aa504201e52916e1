"""DDQN training at the BS (MODEL.md sections 5-6, docs/ddqn.md) in one compiled program.

PureJaxRL style: ``make_train(config, params)`` returns a :class:`Trainer` whose ``init``,
``run`` and ``train`` are pure functions of a :class:`TrainState` pytree; ``jax.vmap(trainer.train)(keys)``
trains seeds. A run is ``lax.scan`` over *chunks*; a chunk is ``steps_per_chunk`` vmapped env
steps, each one ``engine.slot`` per env (the stepping function evaluation uses, through the same
policy and shield) with auto-reset, followed by ``updates_per_step`` gradient updates on a replay
minibatch. The schedule is fixed: a warm-up fills the memory with random actions, epsilon decays
linearly (``optax.linear_schedule``), the target network is synced every ``target_period`` chunks
(``optax.periodic_update``). Every action is the shielded one the BS sent, exploratory ones too.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import TYPE_CHECKING, Any, NamedTuple

import jax
import jax.numpy as jnp
import optax
from flax import struct
from jax.typing import ArrayLike

from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.demos import demonstrate, weighted_margin_loss
from semuav_jax.agents.layouts import layout_pool, restart_state
from semuav_jax.agents.network import QNetwork, num_actions, q_network
from semuav_jax.agents.policy import Explore, explore_policy, input_size, network_input
from semuav_jax.agents.replay import ReplayBuffer, Transition, n_step_transition, replay_init, ring_buffer
from semuav_jax.agents.smdp import option_transitions, pending_init
from semuav_jax.engine import Policy, slot
from semuav_jax.metrics import episode_metrics
from semuav_jax.params import EnvParams, validate_params

if TYPE_CHECKING:
    from semuav_jax.engine import SlotOut
    from semuav_jax.env import EnvState

LOGGED = ("mean_psnr", "return", "arrived", "coverage")  # episode metrics averaged over finished episodes


def train_bandwidths(config: DDQNConfig, params: EnvParams) -> jax.Array:
    """(num_envs,) bandwidth of each training env: spaced over ``bandwidth_range`` evenly or
    geometrically (``bandwidth_spacing``), or params.B."""
    if config.bandwidth_range is None:
        return jnp.full((config.num_envs,), params.B, jnp.float32)
    spaced = jnp.geomspace if config.bandwidth_spacing == "log" else jnp.linspace
    return spaced(*config.bandwidth_range, config.num_envs).astype(jnp.float32)


def epsilon(step: ArrayLike, config: DDQNConfig) -> jax.Array:
    """Linear decay from eps_start to eps_end over the first eps_decay_frac of the learning steps."""
    n = max(1, int(config.eps_decay_frac * config.num_chunks * config.steps_per_chunk))
    return optax.linear_schedule(config.eps_start, config.eps_end, n)(step)


def double_q_target(
    q_next_online: jax.Array, q_next_target: jax.Array, reward: jax.Array, done: jax.Array, gamma: float
) -> jax.Array:
    """y = r + gamma (1 - done) Q_target(s', argmax_a Q_online(s', a)) (van Hasselt et al. 2016)."""
    a_star = jnp.argmax(q_next_online, axis=-1)
    q_eval = jnp.take_along_axis(q_next_target, a_star[..., None], axis=-1)[..., 0]
    return reward + gamma * (1.0 - done) * q_eval


@struct.dataclass
class TrainState:
    """Everything the compiled training loop carries (one agent); checkpointable as a pytree."""

    params: Any
    target_params: Any
    opt_state: Any
    replay: Any  # the replay buffer's state (``replay.Replay`` by default)
    window: Any  # the last n_step one-step transitions of every env (leading axis n_step); options: smdp.Pending
    env_state: Any
    obs: jax.Array
    key: jax.Array
    step: jax.Array  # vmapped env steps taken after warm-up
    updates: jax.Array  # gradient updates
    chunk: jax.Array  # chunks done
    demos: Any = None  # the demonstration memory (``replay.Replay``; agents/demos.py), if demo_steps > 0
    layouts: Any = None  # the numbered training layouts (``layouts.layout_pool``), if the policy numbers devices


class Trainer(NamedTuple):
    """One training run: its static parts and its pure functions (see :func:`make_train`)."""

    config: DDQNConfig
    network: QNetwork
    policy: Policy  # ``policy.explore_policy``: what the envs are stepped with
    env_params: EnvParams  # with one bandwidth per env (leading axis num_envs on B)
    env_axes: Any  # vmap axes of env_params
    tx: optax.GradientTransformation
    buffer: ReplayBuffer
    demo_buffer: ReplayBuffer  # the demonstration memory's functions: a ring buffer whatever ``buffer`` is
    progress: Callable | None
    init: Callable  # key -> TrainState (warm-up included)
    run: Callable  # (TrainState, n_chunks static) -> (TrainState, per-chunk metrics)
    train: Callable  # key -> (TrainState, per-chunk metrics), the whole run


def td_loss(tr: Trainer, params: Any, target_params: Any, batch: Transition) -> tuple[jax.Array, jax.Array]:
    """(Huber loss of Q(s, a) against the double-Q n-step target, Q(s, .) of the batch)."""
    q = tr.network.apply(params, batch.obs)
    q_a = jnp.take_along_axis(q, batch.action[:, None], axis=-1)[:, 0]
    q_next_online = tr.network.apply(params, batch.next_obs)
    q_next_target = tr.network.apply(target_params, batch.next_obs)
    y = double_q_target(q_next_online, q_next_target, batch.reward, batch.done, batch.discount)
    return jnp.mean(optax.huber_loss(q_a, jax.lax.stop_gradient(y))), q


def loss(tr: Trainer, params: Any, target_params: Any, batch: Transition, demo_action: jax.Array | None) -> jax.Array:
    """The TD loss of ``batch``; with ``demo_action``, the expert's choices of the batch's last rows
    (demonstrations), plus their large-margin loss weighted by demo_weight (agents/demos.py)."""
    value, q = td_loss(tr, params, target_params, batch)
    if demo_action is None:
        return value
    n = len(demo_action)
    return value + weighted_margin_loss(tr.config, batch.obs[-n:], q[-n:], demo_action)


def update(tr: Trainer, ts: TrainState, key: jax.Array) -> tuple[TrainState, jax.Array]:
    """One gradient step on a replay minibatch (its last demo_batch rows from the demonstrations,
    when there are any); returns (ts, loss)."""
    batch, demo_action = tr.buffer.sample(ts.replay, key).experience, None
    if ts.demos is not None:
        demos, n = tr.demo_buffer.sample(ts.demos, jax.random.fold_in(key, 1)).experience, tr.config.demo_batch
        batch, demo_action = jax.tree.map(lambda r, d: jnp.concatenate([r[:-n], d]), batch, demos), demos.action
    value, grads = jax.value_and_grad(partial(loss, tr))(ts.params, ts.target_params, batch, demo_action)
    upd, opt_state = tr.tx.update(grads, ts.opt_state, ts.params)
    return ts.replace(params=optax.apply_updates(ts.params, upd), opt_state=opt_state, updates=ts.updates + 1), value


def env_slot(
    tr: Trainer, key: jax.Array, state: EnvState, obs: Any, ps: Any, params: EnvParams, layouts: Any = None
) -> tuple[EnvState, Any, SlotOut, Any, jax.Array, dict[str, jax.Array], Any]:
    """``engine.slot`` for one env, then gymnax's auto-reset (a finished episode restarts with a new
    layout, :func:`restart_state`). Returns (state, obs, SlotOut, obs before the reset, done, episode
    metrics, policy state)."""
    k_step, k_reset = jax.random.split(key)
    new, new_obs, ps, out = slot(tr.policy, jax.random.uniform(k_step), state, obs, ps, params)
    restart = restart_state(k_reset, params, layouts)
    select = lambda r, s: jax.lax.select(new.done, r, s)
    state = jax.tree.map(select, restart, new)
    obs = jax.tree.map(select, tr.policy.observe(restart, params), new_obs)
    return state, obs, out, new_obs, new.done, episode_metrics(new, params), ps


def env_step(
    tr: Trainer, ts: TrainState, key: jax.Array, eps: jax.Array, action: jax.Array | None = None
) -> tuple[TrainState, tuple[jax.Array, dict[str, jax.Array], jax.Array]]:
    """One vmapped env step under epsilon-greedy, ``action`` (E,) in place of the random draws if
    given; the transition enters the n-step window (not yet the memory)."""
    E = tr.config.num_envs
    k_eps, k_rand, k_env = jax.random.split(key, 3)
    n_act = num_actions(tr.env_params, tr.config)
    explore = jax.random.randint(k_rand, (E,), 0, n_act) if action is None else action
    ps = Explore(ts.params, eps, jax.random.uniform(k_eps, (E,)), explore)
    axes = (0, 0, 0, Explore(None, None, 0, 0), tr.env_axes, None)
    c, option = tr.config, tr.config.uses_options
    if option:
        ps, axes = (ps, ts.window.option), axes[:3] + ((axes[3], 0), tr.env_axes, None)
    state, obs, out, final_obs, done, met, ps = jax.vmap(partial(env_slot, tr), axes)(
        jax.random.split(k_env, E), ts.env_state, ts.obs, ps, tr.env_params, ts.layouts
    )
    x, reward = network_input(ts.obs), out.reward * c.reward_scale
    if option:  # one transition per decision (agents/smdp.py), stored here
        batch, valid, window = option_transitions(ts.window, x, ps[1], reward, network_input(final_obs), done, c.gamma)
        ts = ts.replace(replay=tr.buffer.add_where(ts.replay, batch, valid))
    else:
        disc = jnp.full((E,), c.gamma, jnp.float32)
        one = Transition(x, out.action, reward, final_obs, done.astype(jnp.float32), disc)
        window = jax.tree.map(lambda w, x: jnp.concatenate([w[1:], x[None]]), ts.window, one)
    return ts.replace(window=window, env_state=state, obs=obs), (done, met, jnp.mean(out.shielded.astype(jnp.float32)))


def store_step(
    tr: Trainer, ts: TrainState, key: jax.Array, eps: jax.Array
) -> tuple[TrainState, tuple[jax.Array, dict[str, jax.Array], jax.Array]]:
    """:func:`env_step`, then the window's oldest n-step transition into the memory (options:
    :func:`env_step` stored the decisions that ended)."""
    ts, out = env_step(tr, ts, key, eps)
    if tr.config.uses_options:
        return ts, out
    return ts.replace(replay=tr.buffer.add(ts.replay, n_step_transition(ts.window, tr.config.gamma))), out


def init(tr: Trainer, key: jax.Array) -> TrainState:
    """A fresh agent and envs; the n-step window and then the memory filled with random actions."""
    c, E = tr.config, tr.config.num_envs
    k_net, k_env, k_warm, k_run = jax.random.split(key, 4)
    k_warm, k_demo = jax.random.split(k_warm) if c.demo_steps else (k_warm, None)
    one_env = tr.env_params.replace(B=tr.env_params.B[0])  # input size and layouts do not depend on B
    n_in = input_size(one_env, c)
    params = tr.network.init(k_net, jnp.zeros((n_in,), jnp.float32))
    layouts = layout_pool(tr.policy, one_env, jax.random.fold_in(k_env, E))
    restart = lambda k, p: restart_state(k, p, layouts)
    states = jax.vmap(restart, (0, tr.env_axes))(jax.random.split(k_env, E), tr.env_params)
    empty = replay_init(E, n_in).data
    if tr.config.uses_options:
        window = pending_init(empty)
    else:
        window = jax.tree.map(lambda x: jnp.zeros((c.n_step,) + x.shape, x.dtype), empty)
    ts = TrainState(
        params=params,
        target_params=params,
        opt_state=tr.tx.init(params),
        replay=tr.buffer.init(jax.tree.map(lambda x: x[0], empty)),
        window=window,
        env_state=states,
        obs=jax.vmap(tr.policy.observe, (0, tr.env_axes))(states, tr.env_params),
        key=k_run,
        step=jnp.zeros((), jnp.int32),
        updates=jnp.zeros((), jnp.int32),
        chunk=jnp.zeros((), jnp.int32),
        layouts=layouts,
    )
    fill = lambda ts, k: (env_step(tr, ts, k, 1.0)[0], None)
    warm = lambda ts, k: (store_step(tr, ts, k, 1.0)[0], None)
    k_fill, k_warm = jax.random.split(k_warm)
    if not tr.config.uses_options:
        ts, _ = jax.lax.scan(fill, ts, jax.random.split(k_fill, c.n_step - 1))  # fill the window
    ts, _ = jax.lax.scan(warm, ts, jax.random.split(k_warm, c.warmup_steps))
    return demonstrate(tr, ts, k_demo, env_step) if c.demo_steps else ts


def train_step(tr: Trainer, ts: TrainState, _=None) -> tuple[TrainState, dict[str, jax.Array]]:
    """One env step (stored) and ``updates_per_step`` gradient updates; returns (ts, step stats)."""
    key, k_act, k_upd = jax.random.split(ts.key, 3)
    ts = ts.replace(key=key)
    ts, (done, met, shielded) = store_step(tr, ts, k_act, epsilon(ts.step, tr.config))
    ts, losses = jax.lax.scan(partial(update, tr), ts, jax.random.split(k_upd, tr.config.updates_per_step))
    ts = ts.replace(step=ts.step + 1)
    d = done.astype(jnp.float32)
    stats = {k: jnp.sum(d * met[k].astype(jnp.float32)) for k in LOGGED}
    return ts, {"episodes": jnp.sum(d), "loss": jnp.mean(losses), "shield_share": shielded, **stats}


def train_chunk(tr: Trainer, ts: TrainState, _=None) -> tuple[TrainState, dict[str, jax.Array]]:
    """``steps_per_chunk`` train steps and the periodic target sync; returns (ts, chunk metrics)."""
    c = tr.config
    eps = epsilon(ts.step, c)
    ts, s = jax.lax.scan(partial(train_step, tr), ts, None, c.steps_per_chunk)
    chunk = ts.chunk + 1
    target = optax.periodic_update(ts.params, ts.target_params, chunk, c.target_period)
    ts = ts.replace(target_params=target, chunk=chunk)
    if tr.progress is not None:
        jax.debug.callback(tr.progress, chunk)
    n = jnp.maximum(s["episodes"].sum(), 1.0)
    return ts, {
        "env_steps": (ts.step + c.warmup_steps) * c.num_envs,
        "epsilon": eps,
        "episodes": s["episodes"].sum(),
        "loss": s["loss"].mean(),
        "shield_share": s["shield_share"].mean(),
        **{k: s[k].sum() / n for k in LOGGED},
    }


def run(tr: Trainer, ts: TrainState, n_chunks: int) -> tuple[TrainState, dict[str, jax.Array]]:
    """``n_chunks`` chunks (static) from ``ts``."""
    return jax.lax.scan(partial(train_chunk, tr), ts, None, n_chunks)


def make_train(
    config: DDQNConfig, env_params: EnvParams, progress: Callable | None = None, buffer: ReplayBuffer | None = None
) -> Trainer:
    """The training run of one agent; ``jax.vmap(trainer.train)(keys)`` trains seeds.

    ``progress`` (optional, host) is called with the number of chunks done after every chunk, from
    inside the compiled loop (``jax.debug.callback``; once per seed when vmapped), so a progress bar
    can move within a long compiled run. ``buffer`` replaces the replay memory (default
    ``replay.ring_buffer``)."""
    validate_params(env_params)
    if config.uses_options and buffer is not None and buffer.add_where is None:
        raise ValueError("option actions store one transition per decision: the replay memory needs add_where")
    network = q_network(env_params, config)
    updates = config.num_chunks * config.steps_per_chunk * config.updates_per_step
    lr = config.lr if config.lr_end == 1.0 else optax.cosine_decay_schedule(config.lr, updates, config.lr_end)
    tr = Trainer(
        config=config,
        network=network,
        policy=explore_policy(network, config),
        env_params=env_params.replace(B=train_bandwidths(config, env_params)),  # every env its own B (traced)
        env_axes=jax.tree.map(lambda _: None, env_params).replace(B=0),
        tx=optax.chain(optax.clip_by_global_norm(config.max_grad_norm), optax.adam(lr)),
        buffer=ring_buffer(config.buffer_size, config.batch_size) if buffer is None else buffer,
        demo_buffer=ring_buffer(config.buffer_size, config.demo_batch),
        progress=progress,
        init=None,
        run=None,
        train=None,
    )
    return tr._replace(
        init=partial(init, tr), run=partial(run, tr), train=lambda key: run(tr, init(tr, key), config.num_chunks)
    )
