"""The certified bound: an exact solution of a relaxation that counts the travel between range discs
(MODEL.md section 7, v3; derivation in docs/baselines.md, "Bound", eqs. 7.12-7.14).

Relaxation, per layout: data flows only while the UAV ends a slot inside some device's range disc
(radius r_c, eq. 3.5), at most R0 / beta symbols per second in all (one shared band at the best
rate, eq. 2.6), at most M per device. Let S be the set of discs the flight touches. Before it first
touches a disc it is outside all of them, and between the first touches the path must cross the
gap from the discs already touched to the next one: the lengths of these dead stretches sum to at
least the minimum spanning tree of {q0} and S under the gap metric g(i, j) = (||p_i - p_j|| - 2 r_c)+
(from q0: (||q0 - p_j|| - r_c)+), plus the final stretch from S's discs to the arrival disk; with
speed <= v_max, a stretch of length g holds at least g / (v_max tau) - 1 slot ends (eq. 7.12). So
at most b(S) = R0 tau (K - dead slots) / beta symbols (eq. 7.13), and the mean PSNR is at most the
best split of b(S) over the devices of S of their curves' upper concave envelopes (eq. 7.14,
water-filling: the b(S) largest unit gains), maximised over all 2^N subsets S.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import numpy as np

from baselines.bound import _check_keys, peak_rate
from baselines.evaluate import layouts
from semuav_jax.control import range_radius
from semuav_jax.params import EnvParams, validate_params

if TYPE_CHECKING:
    import jax

SAFETY_DB = 1e-4  # float32 rounding of the env's mean PSNR


def envelope_gains(curves: np.ndarray) -> np.ndarray:
    """(I, M) unit gains of each curve's upper concave envelope after a running max (a policy may
    stop a device early): non-increasing along k, summing to max_k C[i, k] - C[i, 0]."""
    c = np.maximum.accumulate(np.asarray(curves, np.float64), axis=-1)
    out = np.empty((len(c), c.shape[1] - 1))
    for i, y in enumerate(c):
        hull = [0]  # upper hull (monotone chain) of the points (k, y_k)
        for k in range(1, len(y)):
            while len(hull) >= 2 and (y[hull[-1]] - y[hull[-2]]) * (k - hull[-1]) <= (y[k] - y[hull[-1]]) * (
                hull[-1] - hull[-2]
            ):
                hull.pop()
            hull.append(k)
        env = np.interp(np.arange(len(y)), hull, y[hull])
        out[i] = np.diff(env)
    return out


@functools.cache
def _subsets(n: int) -> np.ndarray:
    return (np.arange(1 << n)[:, None] >> np.arange(n)) & 1  # (2^n, n) membership


def dead_slots(dev_pos: np.ndarray, params: EnvParams) -> np.ndarray:
    """(E, 2^N) eq. 7.12 for layouts (E, N, 2): slots a flight touching exactly the discs of subset S
    (bit n = device n) must end outside every disc: minimum spanning tree of {q0} and S (Prim over
    subsets) plus the final stretch, each stretch of length g worth (g / (v_max tau) - 1)+ slots."""
    p = np.asarray(dev_pos, np.float64)
    E, n = p.shape[:2]
    rc = float(range_radius(params))
    step = float(params.v_max) * float(params.tau)
    w = lambda g: np.maximum(np.maximum(g, 0.0) / step - 1.0, 0.0)
    q0, q_fin, r_arr = np.asarray(params.q0, np.float64), np.asarray(params.q_fin, np.float64), float(params.r_arr)
    dev = w(np.linalg.norm(p[:, :, None] - p[:, None], axis=-1) - 2 * rc)  # (E, N, N)
    final = w(np.linalg.norm(p - q_fin, axis=-1) - rc - r_arr)  # (E, N)
    attach = np.empty((E, 1 << n, n))  # attach[:, P, k]: cheapest stretch from {q0} and P to disc k
    attach[:, 0] = w(np.linalg.norm(p - q0, axis=-1) - rc)
    tree = np.zeros((E, 1 << n))
    last = np.empty((E, 1 << n))
    last[:, 0] = w(np.linalg.norm(q0 - q_fin) - r_arr)  # no disc touched: straight home from q0
    member = _subsets(n).astype(bool)
    for s in range(1, 1 << n):
        h = s.bit_length() - 1
        attach[:, s] = np.minimum(attach[:, s ^ (1 << h)], dev[:, h])
        k = np.nonzero(member[s])[0]
        tree[:, s] = np.min(tree[:, s ^ (1 << k)] + attach[:, s ^ (1 << k), k], axis=1)
        last[:, s] = np.min(final[:, k], axis=1)
    return tree + last


def layout_bound(dead: np.ndarray, gains: np.ndarray, base: np.ndarray, params: EnvParams) -> float:
    """Eq. 7.14 for one layout: dead (2^N,) slots of eq. 7.12, gains (N, M) of its devices'
    envelopes, base (N,) = C[i_n, 0]. Per subset, the b(S) largest unit gains of its devices: a
    bisection for the b(S)-th largest value lambda, then the prefix sums up to it."""
    n, M = gains.shape
    s0 = peak_rate(params) * float(params.tau) / float(params.beta)  # symbols per slot at best
    budget = np.floor(np.maximum(params.K - dead, 0.0) * s0 * (1 + 1e-5)).astype(np.int64)
    member = _subsets(n)
    G = np.concatenate([np.zeros((n, 1)), np.cumsum(gains, axis=1)], axis=1)  # (N, M + 1) prefix sums
    asc = np.ascontiguousarray(gains[:, ::-1])  # each device's gains, ascending
    vals = np.unique(gains)

    def above(lam: np.ndarray) -> np.ndarray:  # (S, N): units of each device with gain > lam (lam per subset)
        return member * (M - np.stack([np.searchsorted(asc[j], lam, side="right") for j in range(n)], axis=1))

    lo, hi = np.zeros(len(budget), np.int64), np.full(len(budget), len(vals) - 1)
    while np.any(lo < hi):
        mid = (lo + hi) // 2
        fewer = above(vals[mid]).sum(axis=1) < budget
        hi, lo = np.where(fewer, mid, hi), np.where(fewer | (lo == hi), lo, mid + 1)
    lam = vals[lo]
    cnt = above(lam)
    value = (G[np.arange(n), cnt] * member).sum(axis=1) + (budget - cnt.sum(axis=1)) * lam
    full = budget >= member.sum(axis=1) * M
    value = np.where(full, (G[:, M] * member).sum(axis=1), value)
    return float((base.sum() + value.max()) / n)


def travel_bound(keys: jax.Array, params: EnvParams) -> np.ndarray:
    """(E,) eq. 7.14: per-episode upper bound (dB) on the final mean PSNR of any policy that arrives,
    on the episodes run with ``keys`` (their layouts and images)."""
    keys = _check_keys(keys)
    validate_params(params)
    pos, img = (np.asarray(x) for x in layouts(keys, params))
    C = np.asarray(params.C, np.float64)
    gains = envelope_gains(C)
    dead = dead_slots(pos, params)
    return np.array([layout_bound(dead[e], gains[img[e]], C[img[e], 0], params) for e in range(len(pos))]) + SAFETY_DB


def flight_account(trace: dict, keys: jax.Array, params: EnvParams) -> dict:
    """Where a flight stands against the relaxation (docs/baselines.md, "Where the gap lies"): per
    episode (E,) its seconds with data (some device transmitting), without data before the end and
    unused after it, and those of them left while an untouched device was in reach (a round trip
    from q_fin into its range disc at v_max fits in the unused time); the dead seconds eq. 7.12
    allows for the same set of touched discs; and the symbols it received per second with data as
    a share of the best rate R0 / beta."""
    x, done = np.asarray(trace["x"]), np.asarray(trace["done"])
    live = np.concatenate([np.ones_like(done[:, :1]), ~done[:, :-1]], axis=1)
    tau = float(params.tau)
    data = (x.any(-1) & live).sum(1) * tau
    flown = live.sum(1) * tau
    pos = np.asarray(layouts(_check_keys(keys), params)[0])
    touched = (x & live[..., None]).any(1)
    S = (touched * (1 << np.arange(x.shape[-1]))).sum(-1)
    relaxed = np.take_along_axis(dead_slots(pos, params), S[:, None], 1)[:, 0] * tau
    m = np.asarray(trace["m"])[:, -1].sum(-1)
    rate = peak_rate(params) / float(params.beta)
    unused = params.K * tau - flown
    gap = np.maximum(np.linalg.norm(pos - np.asarray(params.q_fin), axis=-1) - float(range_radius(params)), 0.0)
    in_reach = (~touched & (2 * gap / float(params.v_max) <= unused[:, None])).any(-1)
    return {
        "data_s": data,
        "dead_s": flown - data,
        "unused_s": unused,
        "unused_in_reach_s": unused * in_reach,
        "relaxed_dead_s": relaxed,
        "rate_share": m / np.maximum(data * rate, 1e-9),
    }
