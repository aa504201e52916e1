"""The offline planner of MODEL.md section 7 (docs/baselines.md, "Planner"): plan at t = 0, fly the plan.

Planning (host, NumPy): the planner sees the layout, the images and the curves at t = 0. For each
cruise speed of ``PLAN_SPEEDS`` it builds a prize-collecting orienteering problem
(``baselines/orienteering.py``): legs cruising between q0, the devices and q_fin (eq. 7.7), and
per device the visit options of :func:`visit_options` (eq. 7.8): a pass through its range at a
speed of ``PASS_SPEEDS`` or a hover until a share ``TARGETS`` of M symbols, each worth
C[i, k] - C[i, 0] for the k symbols it delivers. The plan of the speed with the highest prize is kept.

Flying (JAX, in the env): :func:`planner` is a pure policy like the baselines. It flies to each
planned device at the plan's speed and slows to the visit's speed w at the edge of its range (to
rest for a hover, eq. 7.3 with ``STOP_BRAKE``); a pass ends at the device, a hover when the
target symbols have arrived. It skips a device when flying there, hovering and then home no
longer fits, and flies home (eq. 7.5) when the time left requires it. The command delays and the
real rates (shared band, edge of range) are the env's.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from baselines import orienteering
from baselines.evaluate import layouts
from semuav_jax import channel
from semuav_jax.control import (
    BRAKE,
    STOP_BRAKE,
    approach_speed,
    home_command,
    range_radius,
    speed_command,
    time_home,
    time_to_pass,
)
from semuav_jax.params import EnvParams

if TYPE_CHECKING:
    from semuav_jax.env import EnvState

PLAN_SPEEDS = (16.0, 20.0, 25.0)  # m/s, cruise speeds the planner chooses from
PASS_SPEEDS = (4.0, 6.0, 8.0, 11.0, 15.0, 20.0)  # m/s, speeds through a device's range
TARGETS = (0.85, 1.0)  # hover options: symbols as a share of M
PLAN_SLACK_S = 18.0  # the plan may book T + this: eqs. 7.7-7.8 over-estimate flight time (docs/baselines.md)
MARGIN_S = 1.0  # slack of the in-flight checks (skip a device, fly home)
SERVICE_STEP_S = 0.25  # service times are rounded up to this grid: the DP is exact and fast on it


@struct.dataclass
class PlanState:
    """Policy state of one episode: the plan (device order, -1 padded; per device the speed w
    through its range, 0 to hover until ``target`` symbols), its cruise speed, the hover symbol
    rate s0 and the index of the current visit."""

    order: jax.Array
    target: jax.Array
    w: jax.Array
    v_p: jax.Array
    s0: jax.Array
    idx: jax.Array
    edge: jax.Array  # metres from the device where a pass has slowed to w: r_c (eq. 7.8) or 0 (eq. 7.11)
    book: jax.Array  # 1: skip a device whose remaining hover no longer fits; 0: hover until leaving is required


def hover_rate(params: EnvParams) -> float:
    """s0: symbols per second of a lone device right below the UAV, R(0) / beta (eq. 2.6)."""
    return float(channel.rest_rate(params)) / float(params.beta)


def _range_symbols(params: EnvParams, n: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """Ground radii r (midpoints over the range radius) and the symbol rate R(r) / beta of a lone device."""
    rc = float(range_radius(params))
    r = (np.arange(n) + 0.5) * rc / n
    return (
        r,
        np.asarray(channel.rate(jnp.asarray(r * r), params.H, params.P_n, params.B, params)) / float(params.beta),
        rc / n,
    )


def visit_options(v: float, params: EnvParams) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 7.8: the visit options of a device at cruise speed v, as arrays over options:
    w (speed through the range; 0 = hover), symbols expected, service seconds (time beyond
    cruising past the device at v), symbol target (M for passes).

    A pass slows from v with STOP_BRAKE a_max to w before the range, crosses the range radius at
    w to the device and speeds up at a_max on leaving it: (v - w)^2 / (2 b a v) + r_c (1 / w - 1 / v)
    + (v - w)^2 / (2 a v) + w / a_max (turning) beyond cruising; it receives the integral of
    R(r) / (beta speed(r)) over both radii. A hover stops over the device (v / (2 b a) + v / (2 a))
    and stays until the target at s0, counting the symbols received on the way in and out.
    Service times are rounded up to SERVICE_STEP_S.
    """
    a, M = float(params.a_max), params.M
    r, sym, dr = _range_symbols(params)
    rc = float(range_radius(params))
    b = STOP_BRAKE * a
    w = np.array([x for x in PASS_SPEEDS if x < v] + [v])
    v_out = np.minimum(v, np.sqrt(w[:, None] ** 2 + 2 * a * r))
    pass_sym = np.sum(sym / w[:, None] + sym / v_out, axis=1) * dr
    pass_time = (v - w) ** 2 / (2 * b * v) + (v - w) ** 2 / (2 * a * v) + rc * (1 / w - 1 / v) + w / a
    credit = np.sum(sym * (1 / np.minimum(v, np.sqrt(2 * b * r)) + 1 / np.minimum(v, np.sqrt(2 * a * r)))) * dr
    k = np.maximum(np.round(np.asarray(TARGETS) * M), min(credit, M))
    hover_time = v / (2 * b) + v / (2 * a) + np.maximum(k - credit, 0.0) / hover_rate(params)
    service = np.ceil(np.concatenate([pass_time, hover_time]) / SERVICE_STEP_S - 1e-9) * SERVICE_STEP_S
    return (
        np.concatenate([w, np.zeros(len(k))]),
        np.minimum(np.concatenate([pass_sym, k]), M),
        service,
        np.concatenate([np.full(len(w), float(M)), k]),
    )


def travel_times(
    start: np.ndarray, dev_pos: np.ndarray, params: EnvParams, v: float, v_now: np.ndarray | None = None
) -> np.ndarray:
    """Eq. 7.7: the legs' seconds (E, N+2, N+2) over the nodes [start (E, 2), devices (E, N, 2), q_fin]
    of E episodes: cruising at v plus one slot of command delay per leg; the first leg adds the time
    to reach cruise, v / (2 a_max) from rest or ||v u - v_now|| / (2 a_max) from the velocity
    ``v_now`` (E, 2), u its course; the last the braking into the arrival disk. Never negative."""
    a, tau = float(params.a_max), float(params.tau)
    E = len(start)
    q_fin = np.broadcast_to(np.asarray(params.q_fin, np.float64), (E, 1, 2))
    nodes = np.concatenate([np.asarray(start)[:, None], dev_pos, q_fin], 1)
    diff = nodes[:, None] - nodes[:, :, None]
    d = np.linalg.norm(diff, axis=-1)
    travel = d / v + tau
    if v_now is None:
        travel[:, 0, :] += v / (2 * a)
    else:
        u0 = diff[:, 0] / np.maximum(d[:, 0, :, None], 1e-6)
        travel[:, 0, :] += np.linalg.norm(v * u0 - v_now[:, None], axis=-1) / (2 * a)
    travel[:, :, -1] += v / (2 * BRAKE * a) - float(params.r_arr) / v
    return np.maximum(travel, 0.0)


def problems(
    dev_pos: np.ndarray, dev_img: np.ndarray, params: EnvParams, v: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The orienteering inputs (travel_s, service_s, prize) of E layouts at cruise speed v, from
    q0 at rest (:func:`travel_times`), and the options' (w, target)."""
    C = np.asarray(params.C, np.float64)
    E, N = dev_pos.shape[:2]
    w, sym, service, target = visit_options(v, params)
    prize = C[dev_img][:, :, np.floor(sym).astype(int)] - C[dev_img][:, :, :1]
    return (
        travel_times(np.broadcast_to(np.asarray(params.q0), (E, 2)), dev_pos, params, v),
        np.ascontiguousarray(np.broadcast_to(service, (E, N, len(w)))),
        np.maximum(prize, 0.0),
        w,
        target,
    )


def make_plans(
    keys: jax.Array, params: EnvParams, speeds: Sequence[float] = PLAN_SPEEDS, workers: int = 2
) -> PlanState:
    """Plans (a PlanState with an episode axis) for the episodes run with ``keys`` (same layouts
    as ``rollout``): for each layout the best plan over ``speeds`` by planned prize."""
    speeds = tuple(float(v) for v in speeds)
    if not speeds or not all(np.isfinite(v) and v > 0 for v in speeds):
        raise ValueError(f"planner speeds must be finite and > 0 m/s, got {speeds}")
    pos, img = (np.asarray(x) for x in layouts(jnp.asarray(keys), params))
    budget = params.K * float(params.tau) + PLAN_SLACK_S
    best = None
    for v in speeds:
        v = min(v, float(params.v_max))
        travel, service, prize, w, target = problems(pos.astype(np.float64), img, params, v)
        order, option, value = orienteering.solve_batch(travel, service, prize, budget, workers=workers)
        o = np.maximum(option, 0)
        new = [order, w[o], target[o], value, np.full(len(pos), v)]
        if best is None:
            best = new
        else:
            better = value > best[3]
            best = [np.where(better.reshape((-1,) + (1,) * (x.ndim - 1)), x, y) for x, y in zip(new, best)]
    order, w, target, _, v_p = best
    E = len(pos)
    return PlanState(
        order=jnp.asarray(order, jnp.int32),
        target=jnp.asarray(target, jnp.float32),
        w=jnp.asarray(w, jnp.float32),
        v_p=jnp.asarray(v_p, jnp.float32),
        s0=jnp.full((E,), hover_rate(params), jnp.float32),
        idx=jnp.zeros((E,), jnp.int32),
        edge=jnp.full((E,), range_radius(params), jnp.float32),
        book=jnp.ones((E,), jnp.float32),
    )


def planner(ps: PlanState, s: EnvState, params: EnvParams) -> tuple[jax.Array, PlanState]:
    """Fly the plan (see the module docstring); the interface of the baselines' policies."""
    left = (params.K - s.t) * params.tau
    N = ps.order.shape[0]

    def done_with(i: jax.Array) -> jax.Array:
        n = ps.order[jnp.minimum(i, N - 1)]
        valid = (i < N) & (n >= 0)
        n = jnp.maximum(n, 0)
        hover = jnp.maximum(ps.target[n] - s.m[n], 0.0) / ps.s0
        need = (
            time_to_pass(s.q, s.v, s.dev_pos[n], ps.v_p, params)
            + hover * (ps.w[n] == 0) * ps.book
            + time_home(s.dev_pos[n], jnp.zeros(2), ps.v_p, params)
        )
        dist = jnp.linalg.norm(s.dev_pos[n] - s.q)
        finished = (s.m[n] >= jnp.minimum(ps.target[n], params.M) - 1e-3) | (
            (ps.w[n] > 0) & (dist <= ps.w[n] * params.tau + 1.0)
        )
        return valid & (finished | (need + MARGIN_S > left))

    idx = jax.lax.while_loop(done_with, lambda i: i + 1, ps.idx)
    n = ps.order[jnp.minimum(idx, N - 1)]
    go = (idx < N) & (n >= 0) & (left > time_home(s.q, s.v, ps.v_p, params) + MARGIN_S)
    n = jnp.maximum(n, 0)
    p = s.dev_pos[n]
    # slow down to w at the edge of range (to rest over the device when w = 0), eq. 7.3
    edge = jnp.where(ps.w[n] > 0, ps.edge, 0.0)
    dist = jnp.linalg.norm(p - s.q)
    speed = jnp.minimum(ps.v_p, jnp.sqrt(ps.w[n] ** 2 + approach_speed(dist - edge, ps.v_p, params, STOP_BRAKE) ** 2))
    to_dev = speed_command(s.q, s.v, p, speed, params)
    a = jnp.where(go, to_dev, home_command(s.q, s.v, ps.v_p, params))
    return a, ps.replace(idx=idx)
