"""The Q-network's input (docs/ddqn.md, "Input"): what the BS knows (MODEL.md section 5), arranged
so that an MLP can use it. Fixed transforms without parameters.

- :func:`table_features` (the paper's acceleration table): the observation of eq. 5.1 with device
  blocks sorted nearest first and a ``tanh(20 x)`` companion for every relative offset;
- :func:`waypoint_features` (waypoint actions, eq. 6.2): device blocks in the order the actions
  address them, each with its remaining PSNR gain and the time slack left after flying through it
  and home (eqs. 7.4-7.5), plus the bandwidth and the hover rate, so one network serves every B;
- :func:`option_features` (options, eq. 6.4, ``option_inputs``): those, and for every option what
  it would bring and cost, read off its device's PSNR curve.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

from semuav_jax import channel
from semuav_jax.actions import OPTION_HOME, OPTION_K, device_order, option_codes, option_fits, option_need
from semuav_jax.agents.options import OptionObs, planned_tour
from semuav_jax.control import time_home, time_via
from semuav_jax.observation import DEVICE_FEATURES, GLOBAL_FEATURES
from semuav_jax.params import EnvParams

if TYPE_CHECKING:
    from semuav_jax.env import EnvState

NEAR_GAIN = 20.0  # tanh(20 x): resolves tens of metres in area-normalized offsets
SLACK_SPEED = 12.0  # m/s: the pass speed at which a device's time slack is computed
B_REF = 20e3  # Hz: the bandwidth feature is log2(B / B_REF)
BANDWIDTH = GLOBAL_FEATURES + 3  # its index in waypoint_features (after the goal's tanh and the slack home)


def table_features(obs: jax.Array) -> jax.Array:
    """The observation (eq. 5.1) made permutation-invariant: device blocks sorted nearest first
    (a device's index carries no meaning on random layouts), and every relative offset (devices and
    goal) with a ``tanh(20 x)`` companion that resolves the ~32 m communication radius, which the
    area normalization squeezes to ~0.03. Works on one observation or a batch."""
    glob, dev = obs[..., :GLOBAL_FEATURES], obs[..., GLOBAL_FEATURES:]
    dev = dev.reshape(dev.shape[:-1] + (-1, DEVICE_FEATURES))
    order = jnp.argsort(jnp.sum(dev[..., :2] ** 2, axis=-1), axis=-1)
    dev = jnp.take_along_axis(dev, order[..., None], axis=-2)
    dev = jnp.concatenate([dev, jnp.tanh(NEAR_GAIN * dev[..., :2])], axis=-1)
    near_goal = jnp.tanh(NEAR_GAIN * glob[..., GLOBAL_FEATURES - 2 :])
    return jnp.concatenate([glob, near_goal, dev.reshape(dev.shape[:-2] + (-1,))], axis=-1)


def waypoint_features(state: EnvState, params: EnvParams) -> jax.Array:
    """The input of a waypoint agent for one ``EnvState``: a flat float32 vector, entries in about [-1, 1].

    Global: q, v, a_prev, time left, goal offset and its tanh, the time slack home (eq. 7.5) / T,
    log2(B / B_REF) and the symbols per slot at a hover (eq. 2.6 at r = 0, share of M). Per device,
    in :func:`device_order`: offset and its tanh, m/M, x, phi and the PSNR still to gain (both by the
    range of C), and the time slack after passing it at SLACK_SPEED and flying home (eqs. 7.4-7.5) / T.
    """
    area = jnp.stack([params.Lx, params.Ly])
    T = params.K * params.tau
    left = (params.K - state.t) * params.tau
    lo, hi = jnp.min(params.C), jnp.max(params.C)
    span = jnp.maximum(hi - lo, 1e-6)
    goal = (params.q_fin - state.q) / area
    hover = channel.rest_rate(params) * params.tau / (params.beta * params.M)
    glob = jnp.concatenate(
        [
            state.q / area,
            state.v / params.v_max,
            state.a_prev / params.a_max,
            jnp.stack([left / T]),
            goal,
            jnp.tanh(NEAR_GAIN * goal),
            jnp.stack(
                [(left - time_home(state.q, state.v, params.v_max, params)) / T, jnp.log2(params.B / B_REF), hover]
            ),
        ]
    )
    order = device_order(state, params)
    pos = state.dev_pos[order]
    off = (pos - state.q) / area

    def slack(p: jax.Array) -> jax.Array:
        return (left - time_via(state.q, state.v, p, SLACK_SPEED, params)) / T

    phi = state.phi[order]
    top = params.C[state.dev_img[order], params.M]
    dev = jnp.concatenate(
        [
            off,
            jnp.tanh(NEAR_GAIN * off),
            (state.m[order] / params.M)[:, None],
            state.x[order][:, None].astype(jnp.float32),
            ((phi - lo) / span)[:, None],
            (jnp.maximum(top - phi, 0.0) / span)[:, None],
            jax.vmap(slack)(pos)[:, None],
        ],
        axis=-1,
    )
    return jnp.concatenate([glob, dev.reshape(-1)]).astype(jnp.float32)


def bandwidth(x: jax.Array) -> jax.Array:
    """(...,) Hz: the bandwidth B at which a :func:`waypoint_features` or :func:`option_features`
    input ``x`` (..., n) was computed, read off its log2(B / B_REF) entry."""
    return B_REF * jnp.exp2(x[..., BANDWIDTH])


def curve_gains(state: EnvState, params: EnvParams) -> jax.Array:
    """(N, len(OPTION_K)): the PSNR device n's curve adds up to k symbols, (C[i_n, min(k, M)] - phi_n)+ (dB)."""
    k = jnp.minimum(jnp.asarray(OPTION_K), params.M).astype(jnp.int32)
    return jnp.maximum(params.C[state.dev_img[:, None], k[None]] - state.phi[:, None], 0.0)


def stay_seconds(k: jax.Array, m: jax.Array, params: EnvParams) -> jax.Array:
    """Seconds a hover takes to bring a device from m to min(k, M) symbols: (min(k, M) - m)+ beta / R(0)."""
    return jnp.maximum(jnp.minimum(k, params.M) - m, 0.0) * params.beta / channel.rest_rate(params)


def option_features(state: EnvState, params: EnvParams, margin: float, shortest: bool = False) -> jax.Array:
    """:func:`waypoint_features`, then for each option c < OPTION_HOME (eq. 6.4) of the device n it
    would serve: the PSNR it adds, C[i_n, k] - phi_n (by the range of C; the curve is what the BS
    knows of the device's image), the seconds its stay takes at the hover rate, (k - m_n)+ beta / R(0),
    and the slack it leaves, time left - flight via n home (eqs. 7.4-7.5) - that stay, both / T,
    and whether it has a device, for the options of time margin ``margin`` s (eq. 7.9) along the tour
    of ``options.planned_tour`` (``shortest``: the devices' numbers). Zeros for an option without a
    device."""
    need = option_need(state, params)
    fits = option_fits(state, params, margin, need)
    order = device_order(state, params)
    tour = planned_tour(OptionObs(None, state.m, fits, order, state.q, state.dev_pos), params, shortest)
    codes, ks = option_codes(OPTION_HOME, state.m, fits, order, tour, params)
    has = codes >= 0
    n = jnp.maximum(codes, 0)
    T = params.K * params.tau
    span = jnp.maximum(jnp.max(params.C) - jnp.min(params.C), 1e-6)
    gain = curve_gains(state, params)[n, jnp.arange(OPTION_HOME) % len(OPTION_K)] / span
    stay = stay_seconds(jnp.where(has, ks, 0.0), state.m[n], params)
    slack = ((params.K - state.t) * params.tau - need[n] - stay) / T
    block = jnp.stack([gain, stay / T, slack, jnp.ones_like(gain)], axis=-1) * has[:, None]
    return jnp.concatenate([waypoint_features(state, params), block.reshape(-1)]).astype(jnp.float32)
