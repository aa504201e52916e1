"""Batched evaluation of any policy in the jitted, vmapped env (MODEL.md sections 7-8).

``run`` is the shared path (baselines and the DDQN): E episodes, one compiled program, the
metrics of MODEL.md section 8. ``baseline_metrics`` is a pure ``(keys, params, v_b, rank) ->
metrics`` that vmaps over ``params.B`` and ``v_b`` without recompiling; ``sweep`` does exactly
that for a grid, its episodes sharded over every device of every process (``semuav_jax.sharding``).
TSP ranks are solved outside jit (``tsp_ranks``, ``baselines.tsp``), each process solving its share.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import numpy.typing as npt
from jax.typing import ArrayLike

from baselines import tsp as tsp_solver
from baselines.policies import DEFAULT_V_B, POLICIES, init_state
from semuav_jax.engine import Policy
from semuav_jax.env import EnvState, reset_state
from semuav_jax.params import EnvParams, validate_params
from semuav_jax.rollout import rollout
from semuav_jax.sharding import map_episodes, split_hosts


def resolve(policy: str | Callable) -> Callable:
    """A policy function from a name of ``POLICIES`` or the function itself."""
    if callable(policy):
        return policy
    if policy not in POLICIES:
        raise ValueError(f"unknown baseline {policy!r}; choose one of {sorted(POLICIES)} or pass a policy function")
    return POLICIES[policy]


@jax.jit
def layouts(keys: jax.Array, params: EnvParams) -> tuple[jax.Array, jax.Array]:
    """Device positions (E, N, 2) and image indices (E, N) of the episodes run with ``keys`` (the same
    reset key split as ``episode``)."""
    s = jax.vmap(lambda k: reset_state(jax.random.split(k)[0], params))(keys)
    return s.dev_pos, s.dev_img


def tsp_ranks(keys: jax.Array, params: EnvParams, workers: int = 2) -> np.ndarray:
    """Rank (E, N) of each device in the shortest open path q0 -> devices -> q_fin of each episode
    (``baselines.tsp``: exact, or OR-Tools above its ``EXACT_MAX_DEVICES``)."""
    pos = np.asarray(layouts(keys, params)[0])
    q0, q_fin = np.asarray(params.q0), np.asarray(params.q_fin)
    if params.layout == "fixed":
        order = tsp_solver.solve_order(pos[0], q0, q_fin)
        orders = np.broadcast_to(order, pos.shape[:2])
    else:  # each process solves its share of the layouts
        orders = split_hosts(lambda lo, hi: tsp_solver.solve_orders(pos[lo:hi], q0, q_fin, workers), len(pos))
    return np.argsort(orders, axis=-1).astype(np.int32)


def check_speeds(v_b: npt.ArrayLike) -> jax.Array:
    """v_b as a float32 array, or a one-line ValueError naming a speed that is not finite and > 0."""
    v = np.atleast_1d(np.asarray(v_b, np.float64))
    bad = v[~(np.isfinite(v) & (v > 0))]
    if bad.size:
        raise ValueError(f"v_b must be finite and > 0 m/s, got {bad[0]}")
    return jnp.asarray(v, jnp.float32)


def run(
    policy: Policy | Callable,
    keys: jax.Array,
    params: EnvParams,
    policy_state: Any,
    state_axes: int | None = 0,
    init_state: EnvState | None = None,
) -> dict[str, jax.Array]:
    """Metrics (dict of (E,) arrays, MODEL.md section 8) of ``policy`` over the episodes ``keys``.

    ``policy_state`` has a leading episode axis, or none with ``state_axes=None`` (e.g. shared
    network weights); ``init_state`` (optional, episode axis) replaces the reset. Pure and
    traceable: one ``semuav_jax.rollout`` program, so it can sit inside a ``vmap``.
    """
    return rollout(policy, keys, params, policy_state, init_state=init_state, state_axes=state_axes)[0]


def baseline_metrics(
    policy: str | Callable, keys: jax.Array, params: EnvParams, v_b: ArrayLike, rank: jax.Array
) -> dict[str, jax.Array]:
    """Pure metrics of a baseline at speed ``v_b`` (traced); vmap it over ``v_b`` or ``params.B``."""
    states = jax.vmap(init_state, in_axes=(None, 0))(v_b, rank)
    return run(resolve(policy), keys, params, states)


def _ranks(
    policy: str | Callable, keys: jax.Array, params: EnvParams, rank: ArrayLike | None, **tsp_kwargs: int
) -> jax.Array:
    if rank is not None:
        return jnp.asarray(rank, jnp.int32)
    if policy == "tsp" or policy is POLICIES["tsp"]:
        return jnp.asarray(tsp_ranks(keys, params, **tsp_kwargs))
    return jnp.broadcast_to(jnp.arange(params.N, dtype=jnp.int32), (len(keys), params.N))


def evaluate(
    policy: str | Callable,
    keys: jax.Array,
    params: EnvParams,
    v_b: npt.ArrayLike = DEFAULT_V_B,
    rank: ArrayLike | None = None,
    **tsp_kwargs: int,
) -> dict[str, np.ndarray]:
    """Metrics (dict of (E,) NumPy arrays) of a baseline over the episodes ``keys``.

    ``policy`` is a name of ``POLICIES`` or a baseline function; the TSP ranks are solved here
    unless ``rank`` (E, N) is given (``tsp_kwargs`` go to :func:`tsp_ranks`).
    """
    validate_params(params)
    v_b = check_speeds(v_b)
    if v_b.size != 1:
        raise ValueError(f"evaluate takes one speed v_b; use sweep for several, got {v_b.size}")
    rank = _ranks(policy, keys, params, rank, **tsp_kwargs)
    return jax.tree.map(np.asarray, baseline_metrics(resolve(policy), keys, params, v_b[0], rank))


@partial(jax.jit, static_argnames=("policy",))
def _sweep(
    policy: Callable, keys: jax.Array, params: EnvParams, v_b: jax.Array, B: jax.Array, rank: jax.Array
) -> dict[str, jax.Array]:
    at_b = lambda b: jax.vmap(lambda v: baseline_metrics(policy, keys, params.replace(B=b), v, rank))(v_b)
    return jax.vmap(at_b)(B)


def sweep(
    policy: str | Callable,
    keys: jax.Array,
    params: EnvParams,
    v_b: npt.ArrayLike = (DEFAULT_V_B,),
    B: npt.ArrayLike | None = None,
    rank: ArrayLike | None = None,
    **tsp_kwargs: int,
) -> dict[str, np.ndarray]:
    """Metrics (dict of (len(B), len(v_b), E) arrays) over a bandwidth x speed grid, one compiled program.

    ``B`` defaults to ``params.B``; every point uses the same episodes (layouts, delays, seeds).
    """
    validate_params(params)
    v_b = check_speeds(v_b)
    B = np.atleast_1d(np.asarray(params.B if B is None else B, np.float64))
    if not np.all(np.isfinite(B) & (B > 0)):
        raise ValueError(f"B must be finite and > 0 Hz, got {B[~(np.isfinite(B) & (B > 0))][0]}")
    rank = _ranks(policy, keys, params, rank, **tsp_kwargs)
    B = jnp.asarray(B, jnp.float32)
    policy = resolve(policy)
    return map_episodes(lambda part: _sweep(policy, part[0], params, v_b, B, part[1]), (jnp.asarray(keys), rank))
