"""Greedy-dwell and TSP-dwell: the fixed rules that stop over devices (MODEL.md section 7, v3).

The same orders as greedy and TSP (``baselines/policies.py``), but the UAV cruises at v_c, brakes
to rest over the target device (eq. 7.3 with ``STOP_BRAKE``) and stays until the device has
delivered k* symbols, or until leaving is required to arrive; then it moves on (docs/baselines.md,
eqs. 7.9-7.10). The three knobs (v_c, k*, margin) are traced values of the policy state, so a
tuning grid over them and the bandwidth is one compiled program (:func:`dwell_sweep`).

- Target (eq. 7.9): device n is a candidate while m_n < k* and flying to it (eq. 7.4 at v_c) and
  from it home at rest (eq. 7.5) fits in the time left less ``margin`` seconds.
- Greedy-dwell takes the nearest candidate, TSP-dwell the first candidate of the TSP order; with
  no candidate the UAV flies home (eq. 7.3 braking into the arrival disk).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np
import numpy.typing as npt
from flax import struct
from jax.typing import ArrayLike

from semuav_jax.control import rest_command, time_via
from semuav_jax.params import EnvParams, validate_params
from semuav_jax.rollout import rollout

if TYPE_CHECKING:
    from semuav_jax.env import EnvState


@struct.dataclass
class DwellState:
    """Knobs of one episode (cruise speed v_c m/s, symbols k* to collect, time margin s) and the
    TSP rank (N,) of each device (unused by greedy-dwell)."""

    v_c: jax.Array
    k_star: jax.Array
    margin: jax.Array
    rank: jax.Array


def init_dwell(v_c: ArrayLike, k_star: ArrayLike, margin: ArrayLike, rank: ArrayLike) -> DwellState:
    return DwellState(
        v_c=jnp.asarray(v_c, jnp.float32),
        k_star=jnp.asarray(k_star, jnp.float32),
        margin=jnp.asarray(margin, jnp.float32),
        rank=jnp.asarray(rank, jnp.int32),
    )


def candidates(ps: DwellState, s: EnvState, params: EnvParams) -> jax.Array:
    """(N,) bool, eq. 7.9: devices short of k* symbols that still fit before flying home."""
    need = jax.vmap(lambda p: time_via(s.q, s.v, p, ps.v_c, params, stop=True))(s.dev_pos)
    left = (params.K - s.t) * params.tau
    fits = need + ps.margin <= left
    return fits & (s.m < jnp.minimum(ps.k_star, params.M) - 1e-3)


def dwell_command(score: jax.Array, ps: DwellState, s: EnvState, params: EnvParams) -> jax.Array:
    """Eq. 7.10: the acceleration that rests over the candidate of lowest ``score``, else flies home."""
    return rest_command(s.q, s.v, s.dev_pos, score, candidates(ps, s, params), ps.v_c, ps.v_c, params)


def greedy_dwell(ps: DwellState, s: EnvState, params: EnvParams) -> tuple[jax.Array, DwellState]:
    """Greedy-dwell: the nearest candidate (eq. 7.9)."""
    return dwell_command(jnp.linalg.norm(s.dev_pos - s.q, axis=-1), ps, s, params), ps


def tsp_dwell(ps: DwellState, s: EnvState, params: EnvParams) -> tuple[jax.Array, DwellState]:
    """TSP-dwell: the first candidate of the TSP order ``ps.rank``."""
    return dwell_command(ps.rank.astype(jnp.float32), ps, s, params), ps


DWELL_POLICIES = {"greedy-dwell": greedy_dwell, "tsp-dwell": tsp_dwell}


def check_knobs(v_c: ArrayLike, k_star: ArrayLike, margin: ArrayLike, params: EnvParams) -> list[jax.Array]:
    """The knob grids as float32 arrays, or a one-line ValueError naming the first bad value:
    v_c finite and > 0 m/s, k* in (0, M], margin finite (s; < 0 trusts eqs. 7.4-7.5, which over-estimate)."""
    out = []
    for name, x, ok, rule in (
        ("v_c", v_c, lambda a: np.isfinite(a) & (a > 0), "finite and > 0 m/s"),
        ("k_star", k_star, lambda a: np.isfinite(a) & (a > 0) & (a <= params.M), f"in (0, M = {params.M}]"),
        ("margin", margin, np.isfinite, "finite (s)"),
    ):
        a = np.atleast_1d(np.asarray(x, np.float64))
        if a.ndim != 1 or a.size == 0:
            raise ValueError(f"{name} must be a number or a 1-D list of numbers, got {x!r}")
        bad = a[~ok(a)]
        if bad.size:
            raise ValueError(f"{name} must be {rule}, got {bad[0]:g}")
        out.append(jnp.asarray(a, jnp.float32))
    return out


def dwell_metrics(
    policy: Callable,
    keys: jax.Array,
    params: EnvParams,
    v_c: jax.Array,
    k_star: jax.Array,
    margin: jax.Array,
    rank: jax.Array,
) -> dict[str, jax.Array]:
    """Pure episode metrics (dict of (E,)) of a dwell policy at traced knobs; vmap over any of them."""
    states = jax.vmap(init_dwell, in_axes=(None, None, None, 0))(v_c, k_star, margin, rank)
    return rollout(policy, keys, params, states)[0]


@partial(jax.jit, static_argnames=("policy",))
def _grid(
    policy: Callable, keys: jax.Array, params: EnvParams, knobs: jax.Array, B: jax.Array, rank: jax.Array
) -> dict[str, jax.Array]:
    def at(b: jax.Array, kn: jax.Array) -> dict[str, jax.Array]:
        return dwell_metrics(policy, keys, params.replace(B=b), kn[0], kn[1], kn[2], rank)

    return jax.vmap(lambda b: jax.lax.map(lambda kn: at(b, kn), knobs))(B)


def dwell_sweep(
    name: str,
    keys: jax.Array,
    params: EnvParams,
    v_c: ArrayLike,
    k_star: ArrayLike,
    margin: ArrayLike,
    B: ArrayLike,
    rank: ArrayLike,
) -> dict:
    """Metrics (dict of (len(B), G, E) arrays) of ``name`` over the full grid v_c x k* x margin
    (G points, v_c slowest) at each bandwidth: one compiled program, the same episodes everywhere."""
    if name not in DWELL_POLICIES:
        raise ValueError(f"unknown dwell baseline {name!r}; choose one of {sorted(DWELL_POLICIES)}")
    validate_params(params)
    v_c, k_star, margin = check_knobs(v_c, k_star, margin, params)
    knobs = jnp.stack([g.ravel() for g in jnp.meshgrid(v_c, k_star, margin, indexing="ij")], axis=-1)
    B = jnp.asarray(np.atleast_1d(B), jnp.float32)
    return jax.tree.map(np.asarray, _grid(DWELL_POLICIES[name], keys, params, knobs, B, jnp.asarray(rank, jnp.int32)))


def grid_points(v_c: npt.ArrayLike, k_star: npt.ArrayLike, margin: npt.ArrayLike) -> list[tuple[float, float, float]]:
    """The (v_c, k*, margin) of each grid point, in :func:`dwell_sweep`'s order."""
    return [
        (float(a), float(b), float(c))
        for a in np.atleast_1d(v_c)
        for b in np.atleast_1d(k_star)
        for c in np.atleast_1d(margin)
    ]
