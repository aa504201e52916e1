"""The environment of MODEL.md section 3, as a gymnax 1.0 environment.

``transition`` is one slot driven by a continuous acceleration (what the baselines command);
``SemUAVEnv.step_env`` maps a discrete action index onto it (the paper's table, eq. 6.1, or the
waypoint actions, eq. 6.2) and gymnax's ``Environment.step`` adds the auto-reset. Everything is
pure and jittable. ``make`` builds the environment and its parameters by id, like ``gymnax.make``.
``EnvState`` is defined in ``semuav_jax.state`` (the parts of a slot read it) and handed on here.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from gymnax.environments import environment, spaces
from jax.typing import ArrayLike

from semuav_jax import channel, kinematics, quality
from semuav_jax.actions import ENV_ACTION_MODES, num_actions, to_accel
from semuav_jax.observation import obs_bounds, obs_size, observation
from semuav_jax.params import EnvParams, make_params, params_valid, validate_params
from semuav_jax.reward import reward
from semuav_jax.state import EnvState

ENV_ID = "SemUAV-v0"


def initial_state(dev_pos: ArrayLike, dev_img: ArrayLike, params: EnvParams) -> EnvState:
    """The state at t = 0 for a given layout: q = q0, v = a = 0, nothing received."""
    N = dev_pos.shape[0]
    return EnvState(
        q=jnp.asarray(params.q0, jnp.float32),
        v=jnp.zeros(2),
        a_prev=jnp.zeros(2),
        t=jnp.zeros((), jnp.int32),
        m=jnp.zeros(N),
        phi=quality.psnr(params.C, dev_img, jnp.zeros(N)),
        x=jnp.zeros(N, bool),
        dev_pos=dev_pos,
        dev_img=dev_img,
        delay=jnp.zeros(()),
        arrived=jnp.zeros((), bool),
        done=jnp.zeros((), bool),
        ret=jnp.zeros(()),
    )


def sample_layout(key: jax.Array, params: EnvParams) -> tuple[jax.Array, jax.Array]:
    """Device positions uniform in the area and image indices uniform over C's rows (with replacement)."""
    kp, ki = jax.random.split(key)
    area = jnp.stack([params.Lx, params.Ly])
    pos = jax.random.uniform(kp, (params.N, 2)) * area
    img = jax.random.randint(ki, (params.N,), 0, params.C.shape[0])
    return pos, img


def reset_state(key: jax.Array, params: EnvParams) -> EnvState:
    """Initial state: a fresh random layout, or the fixed one of ``params`` (MODEL.md section 1)."""
    if params.layout == "fixed":
        return initial_state(params.device_pos, params.device_img, params)
    return initial_state(*sample_layout(key, params), params)


def bandwidth_shares(x: jax.Array, B: ArrayLike) -> jax.Array:
    """Eq. 3.6: OFDMA splits B equally among the k transmitting devices, B_n = B / max(k, 1) (0 if silent)."""
    return jnp.where(x, B / jnp.maximum(jnp.sum(x), 1).astype(jnp.float32), 0.0)


def transition(key: jax.Array, state: EnvState, accel: ArrayLike, params: EnvParams) -> tuple[EnvState, jax.Array]:
    """One slot (MODEL.md section 3) under a continuous acceleration command.

    Returns ``(state', reward)``. Once ``state.done`` the state is frozen and the reward is 0, so
    no data is collected after the episode ends. The key draws the processing delay (eq. 3.1).
    """
    return transition_u(jax.random.uniform(key), state, accel, params)


def transition_u(u: ArrayLike, state: EnvState, accel: ArrayLike, params: EnvParams) -> tuple[EnvState, jax.Array]:
    """``transition`` given the slot's uniform draw u ~ U(0, 1) of the processing delay.

    ``rollout`` draws all K of an episode at once, outside the slot loop (faster on CPU).
    """
    a = jnp.clip(accel, -params.a_max, params.a_max)
    delay = kinematics.command_delay(u, state.q, params)
    q, v = kinematics.move(state.q, state.v, state.a_prev, a, delay, params)
    diff = state.dev_pos - q
    r2 = jnp.sum(diff * diff, axis=-1)
    # Eq. 3.5: 3-D range test and transmit set
    x = (r2 + params.H * params.H <= params.D_com * params.D_com) & (state.m < params.M)
    r = channel.rate(r2, params.H, params.P_n, bandwidth_shares(x, params.B), params)
    # Eq. 3.7: ordered latent, partial reception
    m = jnp.minimum(float(params.M), state.m + jnp.where(x, r * (params.tau / params.beta), 0.0))
    t = state.t + 1
    arrived = jnp.sum((q - params.q_fin) ** 2) <= params.r_arr**2
    new = state.replace(
        q=q,
        v=v,
        a_prev=a,
        t=t,
        m=m,
        phi=quality.psnr(params.C, state.dev_img, m),
        x=x,
        delay=delay,
        arrived=arrived,
        done=arrived | (t >= params.K) | kinematics.outside_airspace(q, params),
    )
    rew = reward(state, new, params)
    new = new.replace(ret=state.ret + rew)
    frozen = jax.tree.map(lambda old, nxt: jnp.where(state.done, old, nxt), state, new)
    return frozen, jnp.where(state.done, 0.0, rew)


class SemUAVEnv(environment.Environment[EnvState, EnvParams]):
    """gymnax ``Environment``: observation eq. 5.1, actions the paper's table of accelerations
    (eq. 6.1, ``actions="table"``) or the waypoint actions of eq. 6.2 (``actions="waypoint"``).

    ``step(key, state, action, params)`` (inherited) returns ``(obs, state, reward, terminated,
    truncated, info)`` and resets on the end of an episode. ``terminated`` is ``state.done``
    (eq. 3.9): arrival, t = K, or leaving the airspace (eq. 3.10). Reaching t = K is a true
    terminal, not a time-limit truncation: the time left (K - t)/K is part of the observation
    (eq. 5.1) and the miss is penalized in that slot (eq. 4.5), so nothing lies beyond t = K to
    bootstrap from; ``truncated`` is always False. ``info`` holds ``discount``, ``arrived``,
    ``delay`` (eq. 3.1) and ``valid`` (False when a parameter traced under the caller's ``jit`` is
    out of range, ``params.params_valid``), plus gymnax's ``terminated``, ``truncated`` and
    ``final_observation``. ``reset`` and ``step`` validate concrete parameters first (one-line
    ValueError), once per ``EnvParams`` object. Subclasses change what the agent sees by
    overriding ``get_obs`` and ``observation_space``.
    """

    def __init__(self, params: EnvParams | None = None, actions: str = "table") -> None:
        if actions not in ENV_ACTION_MODES:
            raise ValueError(f"actions must be one of {ENV_ACTION_MODES}, got {actions!r}")
        self._params = params
        self.actions = actions
        self._checked = None  # the last EnvParams object validated

    def _check(self, params: EnvParams | None) -> EnvParams:
        params = self.default_params if params is None else params
        if params is not self._checked:
            validate_params(params)
            self._checked = params
        return params

    def reset(self, key: jax.Array, params: EnvParams | None = None) -> tuple[jax.Array, EnvState]:
        return super().reset(key, self._check(params))

    def step(
        self, key: jax.Array, state: EnvState, action: ArrayLike, params: EnvParams | None = None
    ) -> tuple[jax.Array, EnvState, jax.Array, jax.Array, dict[str, Any]]:
        params = self._check(params)
        self._check_action(state, action, params)
        return super().step(key, state, action, params)

    def _check_action(self, state: EnvState, action: ArrayLike, params: EnvParams) -> None:
        """ValueError (one line) for a state of another N, an action that is not an integer, or a
        concrete action out of range (a traced one out of range makes ``info["valid"]`` False)."""
        if np.shape(state.m)[-1:] != (params.N,):
            raise ValueError(f"state has {np.shape(state.m)[-1]} devices but params N = {params.N}")
        n = num_actions(self.actions, params)
        dtype = getattr(action, "dtype", None) if isinstance(action, jax.core.Tracer) else np.asarray(action).dtype
        if dtype is None or not np.issubdtype(dtype, np.integer):  # bool is not an integer dtype
            raise ValueError(f"action must be an integer in [0, {n}), got {action!r}")
        if not isinstance(action, jax.core.Tracer):
            a = np.asarray(action)
            if a.ndim != 0 or not 0 <= int(a) < n:
                raise ValueError(f"action must be an integer in [0, {n}), got {action!r}")

    @property
    def default_params(self) -> EnvParams:
        if self._params is None:
            self._params = make_params()
        return self._params

    @property
    def name(self) -> str:
        return ENV_ID

    @property
    def num_actions(self) -> int:
        return num_actions(self.actions, self.default_params)

    def action_space(self, params: EnvParams | None = None) -> spaces.Discrete:
        return spaces.Discrete(num_actions(self.actions, params or self.default_params))

    def observation_space(self, params: EnvParams | None = None) -> spaces.Box:
        params = params or self.default_params
        low, high = obs_bounds(params)
        return spaces.Box(low, high, (obs_size(params),), jnp.float32)

    def get_obs(self, state: EnvState, params: EnvParams | None = None, key: jax.Array | None = None) -> jax.Array:
        return observation(state, params or self.default_params)

    def is_terminated(self, state: EnvState, params: EnvParams | None = None) -> jax.Array:
        return state.done

    def is_truncated(self, state: EnvState, params: EnvParams | None = None) -> jax.Array:
        return jnp.zeros((), bool)

    def reset_env(self, key: jax.Array, params: EnvParams) -> tuple[jax.Array, EnvState]:
        state = reset_state(key, params)
        return self.get_obs(state, params), state

    def step_env(
        self, key: jax.Array, state: EnvState, action: ArrayLike, params: EnvParams
    ) -> tuple[jax.Array, EnvState, jax.Array, jax.Array, dict[str, Any]]:
        new, rew = transition(key, state, to_accel(self.actions, action, state, params), params)
        in_range = (action >= 0) & (action < num_actions(self.actions, params))
        info = {
            "discount": self.discount(new, params),
            "arrived": new.arrived,
            "delay": new.delay,
            "valid": params_valid(params) & in_range,
        }
        return self.get_obs(new, params), new, rew, new.done, info


def make(env_id: str, actions: str = "table", **params: Any) -> tuple[SemUAVEnv, EnvParams]:
    """``(env, env_params)`` for an environment id, as ``gymnax.make``; ``actions`` is the action
    mode ("table", eq. 6.1, or "waypoint", eq. 6.2), ``params`` are ``make_params`` overrides."""
    if env_id != ENV_ID:
        raise ValueError(f"unknown environment id {env_id!r}; known ids: {ENV_ID}")
    env = SemUAVEnv(make_params(**params), actions)
    return env, env.default_params
