"""The exact receding-horizon planner (MODEL.md section 7, v3; docs/baselines.md "Exact planner").

Every ``REPLAN_EVERY_S`` seconds it solves, from the current state of each episode (position,
velocity, symbols received, time left), the orienteering problem with variable profits exactly:
Held-Karp over device subsets and end devices with the dwell allocated by a multiple-choice
knapsack on a 0.25 s grid (``baselines/orienteering.py``). A device's options (eq. 7.11) are the
passes of eq. 7.8 and hovers until k symbols for every k of ``HOVER_SYMBOLS``, each worth
C[i, k_after] - C[i, m_n] given the m_n symbols already received. The plan is flown by the
planner's policy (``baselines/planner.planner``: the same delayed commands and in-flight checks);
an episode that is resting over a device it has not finished keeps its plan until it leaves.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import jax
import numpy as np

from baselines import orienteering
from baselines.planner import SERVICE_STEP_S, PlanState, _range_symbols, hover_rate, planner, travel_times
from semuav_jax.control import STOP_BRAKE, range_radius
from semuav_jax.params import EnvParams, validate_params
from semuav_jax.rollout import rollout_replanned

if TYPE_CHECKING:
    from semuav_jax.env import EnvState

PASS_SPEEDS = (3.0, 6.0, 10.0, 15.0)  # m/s at the device (eq. 7.11)
PLAN_SPEEDS = (25.0,)  # m/s, cruise speeds of the first plan; later plans keep the one chosen
HOVER_SYMBOLS = (16, 32, 48, 64, 96, 128, 192, 256)  # stop targets (symbols, capped at M)
REPLAN_EVERY_S = 12.0  # seconds between two plans
TURN_SHARE = 0.5  # share of w / a_max booked for turning at a device (the angle is the route's)
SLACK_SHARE = 0.1  # a plan may book the time left x (1 + this): the legs over-estimate the flight


def options(v: float, m: np.ndarray, params: EnvParams) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 7.11 at cruise speed v for devices holding m (E, N) symbols: w (L,) (0 = a stop), the
    symbols after the visit (E, N, L), the service seconds (E, N, L, on the 0.25 s grid) and the
    symbol target (E, N, L) that ends the visit in flight (M for a pass).

    A pass at w brakes with b = STOP_BRAKE a_max so as to cross the device at w and speeds up at
    a_max after it (speed sqrt(w^2 + 2 b x) at x metres from the device): (v - w)^2 / (2 v)
    (1 / b + 1 / a) + w / a_max (turning) beyond cruising; it receives the integral of
    R(r) / (beta speed(r)) over the range radius on both sides. A stop for k symbols brakes
    towards rest over the device and leaves as soon as k have arrived: at x_k metres from it when
    the way in delivers them (the pass cost at w = sqrt(2 b x_k), plus the symbols of the way out
    from x_k), else after resting at s0 = R(0) / beta for the rest.
    """
    a, M = float(params.a_max), params.M
    r, sym, dr = _range_symbols(params)
    b = STOP_BRAKE * a
    w = np.array([x for x in PASS_SPEEDS if x < v] + [v])
    inb = lambda w: sym / np.minimum(v, np.sqrt(np.asarray(w)[..., None] ** 2 + 2 * b * r)) * dr
    out = lambda w: sym / np.minimum(v, np.sqrt(np.asarray(w)[..., None] ** 2 + 2 * a * r)) * dr
    stop = lambda w: (v - w) ** 2 / (2 * v) * (1 / b + 1 / a) + TURN_SHARE * w / a
    pass_sym = (inb(w) + out(w)).sum(-1)
    s_in = np.cumsum(inb(0.0)[::-1])[::-1]  # symbols of the way in from the edge down to r (descending)
    s_out = np.array(
        [np.sum(sym[i:] / np.minimum(v, np.sqrt(2 * b * r[i] + 2 * a * (r[i:] - r[i])))) * dr for i in range(len(r))]
    )  # way out from r, leaving at the speed sqrt(2 b r) of the way in
    k = np.minimum(np.asarray(HOVER_SYMBOLS, np.float64), M)
    m = np.asarray(m, np.float64)[..., None]
    need = np.maximum(k - m, 0.0)
    x = np.interp(need, s_in[::-1], r[::-1])  # where the way in has delivered ``need``
    u = np.sqrt(2 * b * x)
    early = need <= s_in[0]
    stop_time = np.where(early, stop(u), stop(0.0) + np.maximum(need - s_in[0] - s_out[0], 0.0) / hover_rate(params))
    stop_after = np.where(early, m + need + np.interp(x, r, s_out), np.maximum(k, m + s_in[0]) + s_out[0])
    shape = m.shape[:-1] + (len(w) + len(k),)
    service = np.concatenate([np.broadcast_to(stop(w), m.shape[:-1] + w.shape), stop_time], axis=-1)
    service = np.ceil(service / SERVICE_STEP_S - 1e-9) * SERVICE_STEP_S
    after = np.minimum(np.concatenate([m + pass_sym, stop_after], axis=-1), M)
    target = np.broadcast_to(np.concatenate([np.full(len(w), float(M)), k]), shape)
    return np.concatenate([w, np.zeros(len(k))]), after, service, target


def problems(
    q: np.ndarray,
    v_now: np.ndarray,
    m: np.ndarray,
    t: np.ndarray,
    dev_pos: np.ndarray,
    dev_img: np.ndarray,
    params: EnvParams,
    v: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Orienteering inputs of E episodes from their current states at cruise speed v: travel
    (E, N+2, N+2) over [q, devices, q_fin] (eq. 7.7: cruise plus one slot of command delay, the
    first leg plus ||v u - v_now|| / (2 a_max) to reach cruise, the last the braking into the
    arrival disk; ``planner.travel_times``), service, prize (E, N, L), the budget (E,) and the
    options' (w, target)."""
    w, after, service, target = options(v, m, params)
    C = np.asarray(params.C, np.float64)
    rows = C[dev_img]  # (E, N, M + 1)
    now = np.take_along_axis(rows, np.floor(m).astype(int)[..., None], -1)
    prize = np.maximum(np.take_along_axis(rows, np.floor(after).astype(int), -1) - now, 0.0)
    left = np.maximum(params.K - np.asarray(t, np.float64), 0.0) * float(params.tau)
    travel = travel_times(q, dev_pos, params, v, v_now)
    return travel, service, prize, left * (1.0 + SLACK_SHARE), w, target


def _solve(
    states: EnvState, params: EnvParams, v: float, workers: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(order, w, target per device, planned prize) of the episodes ``states`` at cruise speed v."""
    f = lambda x: np.asarray(x, np.float64)
    travel, service, prize, budget, w, target = problems(
        f(states.q),
        f(states.v),
        f(states.m),
        np.asarray(states.t),
        f(states.dev_pos),
        np.asarray(states.dev_img),
        params,
        v,
    )
    order, option, value = orienteering.solve_batch(travel, service, prize, budget, workers=workers)
    o = np.maximum(option, 0)
    return order, w[o], np.take_along_axis(target, o[..., None], -1)[..., 0], value


def _resting(states: EnvState, ps: PlanState, params: EnvParams) -> np.ndarray:
    """(E,) bool: the episode rests in range of its current hover device, short of its target."""
    N = ps.order.shape[1]
    idx = np.minimum(np.asarray(ps.idx), N - 1)
    n = np.maximum(np.take_along_axis(np.asarray(ps.order), idx[:, None], 1)[:, 0], 0)
    pick = lambda x: np.take_along_axis(np.asarray(x), n[:, None], 1)[:, 0]
    dev = np.take_along_axis(np.asarray(states.dev_pos), n[:, None, None], 1)[:, 0]
    near = np.linalg.norm(dev - np.asarray(states.q), axis=-1) <= float(range_radius(params))
    return (np.asarray(ps.idx) < N) & (pick(ps.w) == 0) & near & (pick(states.m) < pick(ps.target) - 1e-3)


def make_replanner(
    params: EnvParams, speeds: Sequence[float] = PLAN_SPEEDS, workers: int = 2
) -> Callable[[EnvState, PlanState | None], PlanState]:
    """``replan(states, plans) -> plans`` for :func:`semuav_jax.rollout.rollout_replanned`: the
    first call plans at every speed of ``speeds`` and keeps the best planned prize per episode;
    later calls re-plan every episode that is neither done nor resting (``_resting``) at its speed."""
    speeds = tuple(min(float(v), float(params.v_max)) for v in speeds)
    if not speeds or not all(np.isfinite(v) and v > 0 for v in speeds):
        raise ValueError(f"planner speeds must be finite and > 0 m/s, got {speeds}")
    s0 = hover_rate(params)

    def replan(states: EnvState, ps: PlanState | None) -> PlanState:
        E = states.m.shape[0]
        if ps is None:
            best, v_p = None, np.zeros(E)
            for v in speeds:
                new = _solve(states, params, v, workers)
                better = np.full(E, True) if best is None else new[3] > best[3]
                best = (
                    new
                    if best is None
                    else [np.where(better.reshape((-1,) + (1,) * (x.ndim - 1)), x, y) for x, y in zip(new, best)]
                )
                v_p = np.where(better, v, v_p)
            (order, w, target), idx = best[:3], np.zeros(E, np.int32)
        else:
            v_p, idx = np.asarray(ps.v_p, np.float64), np.array(ps.idx)
            order, w, target = (np.array(x) for x in (ps.order, ps.w, ps.target))
            todo = ~np.asarray(states.done) & ~_resting(states, ps, params)
            host = jax.tree.map(np.asarray, states)
            for v in np.unique(v_p[todo]):
                sel = todo & (v_p == v)
                order[sel], w[sel], target[sel], _ = _solve(
                    jax.tree.map(lambda x, sel=sel: x[sel], host), params, float(v), workers
                )
            idx[todo] = 0
        zeros = np.zeros(E, np.float32)
        return PlanState(
            order=order.astype(np.int32),
            target=target.astype(np.float32),
            w=w.astype(np.float32),
            v_p=v_p.astype(np.float32),
            s0=np.full(E, s0, np.float32),
            idx=idx.astype(np.int32),
            edge=zeros,
            book=zeros,
        )

    return replan


def fly(
    keys: jax.Array,
    params: EnvParams,
    every_s: float = REPLAN_EVERY_S,
    speeds: Sequence[float] = PLAN_SPEEDS,
    workers: int = 2,
    trace: bool = False,
) -> tuple[dict[str, np.ndarray], dict[str, jax.Array] | None]:
    """``(metrics, trace)`` of the receding-horizon planner on the episodes ``keys`` (the same
    layouts and delays as ``rollout``): NumPy (E,) metrics of MODEL.md section 8 and, with
    ``trace``, the per-slot trace of ``semuav_jax.rollout``."""
    validate_params(params)
    if not (np.isfinite(every_s) and every_s > 0):
        raise ValueError(f"planner horizon (re-plan interval) must be finite and > 0 s, got {every_s}")
    every = max(1, round(every_s / float(params.tau)))
    m, tr = rollout_replanned(planner, keys, params, make_replanner(params, speeds, workers), every, trace)
    return jax.tree.map(np.asarray, m), tr
