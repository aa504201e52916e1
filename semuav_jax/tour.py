"""Paths through the devices (docs/model.md eq. 6.5), in JAX so the BS plans them inside
``jit``/``vmap``:

- :func:`tour_order`: a short open path from the UAV through the unfinished devices, re-planned at
  every decision: nearest neighbour, then local search with both ends fixed (the best 2-opt reversal
  or single-device relocation, TOUR_MOVES times); ``benchmarks/tour.py`` measures it against Held-Karp;
- :func:`shortest_path`: the shortest open path q -> every device -> q_fin, exact (Held-Karp), planned
  once per layout: the order TSP-dwell follows (eq. 7.8), by which the BS may number the devices
  (:func:`numbered_order`).
"""

from __future__ import annotations

import functools
import itertools

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

TOUR_MOVES = 4  # improving moves per plan
SHORTEST_MAX_DEVICES = 12  # Held-Karp: 2^N x N path lengths per layout


def tour_order(
    q: ArrayLike, dev_pos: ArrayLike, live: ArrayLike, q_fin: ArrayLike, moves: int = TOUR_MOVES
) -> jax.Array:
    """(N,) device indices: the live devices in the order of a short path q -> live devices -> q_fin
    (eq. 6.5), then the others. A device that is not live sits at q_fin, so it costs nothing at the
    path's end and the local search moves it there."""
    q, q_fin = jnp.asarray(q, jnp.float32), jnp.asarray(q_fin, jnp.float32)
    live = jnp.asarray(live)
    pos = jnp.where(live[:, None], jnp.asarray(dev_pos, jnp.float32), q_fin)
    n = pos.shape[0]
    nodes = jnp.concatenate([q[None], pos, q_fin[None]])
    D = jnp.linalg.norm(nodes[:, None] - nodes[None], axis=-1)

    def nearest(c: tuple[jax.Array, jax.Array], _: None) -> tuple[tuple[jax.Array, jax.Array], jax.Array]:
        at, left = c
        j = jnp.argmin(jnp.where(left, D[at, 1:-1], jnp.inf))
        return (j + 1, left.at[j].set(False)), j + 1

    _, inner = jax.lax.scan(nearest, (jnp.int32(0), jnp.ones(n, bool)), None, length=n)
    path = jnp.concatenate([jnp.zeros(1, jnp.int32), inner.astype(jnp.int32), jnp.full(1, n + 1, jnp.int32)])
    idx = jnp.arange(n + 2)
    upper = idx[:-1, None] < idx[None, :-1]
    inner_pos = (idx >= 1) & (idx <= n)
    movable = inner_pos[:, None] & (idx[None, :-1] != idx[:, None]) & (idx[None, :-1] != idx[:, None] - 1)

    def improve(path: jax.Array, _: None) -> tuple[jax.Array, None]:
        a, b = path[:-1], path[1:]  # edge e joins a_e -> b_e
        ab = D[a, b]
        # 2-opt: reversing b_i .. a_j replaces edges i, j by a_i -> a_j and b_i -> b_j
        rev = jnp.where(upper, D[a[:, None], a[None]] + D[b[:, None], b[None]] - ab[:, None] - ab[None], 0.0)
        # relocation: the device at position p moves into edge e
        out = D[jnp.roll(path, 1), path] + D[path, jnp.roll(path, -1)] - D[jnp.roll(path, 1), jnp.roll(path, -1)]
        move = D[a[None], path[:, None]] + D[path[:, None], b[None]] - ab[None] - out[:, None]
        move = jnp.where(movable, move, 0.0)
        i, j = jnp.unravel_index(jnp.argmin(rev), rev.shape)
        p, e = jnp.unravel_index(jnp.argmin(move), move.shape)
        reversed_ = jnp.where((idx > i) & (idx <= j), i + 1 + j - idx, idx)
        ahead = jnp.where(idx == e, p, jnp.where((idx >= p) & (idx < e), idx + 1, idx))
        back = jnp.where(idx == e + 1, p, jnp.where((idx > e + 1) & (idx <= p), idx - 1, idx))
        src = jnp.where(rev[i, j] <= move[p, e], reversed_, jnp.where(e >= p, ahead, back))
        return jnp.where(jnp.minimum(rev[i, j], move[p, e]) < -1e-3, path[src], path), None

    path, _ = jax.lax.scan(improve, path, None, length=moves)
    order = path[1:-1] - 1
    return order[jnp.argsort(~live[order], stable=True)]


@functools.cache
def _subsets(n: int) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], ...]:
    """Per subset size r >= 2: for every subset S of size r and j in S, the flat index S n + j, the
    flat indices (S \\ j) n + i of the i in S \\ j, those i, and j."""
    out = []
    for r in range(2, n + 1):
        dst, src, ii, jj = [], [], [], []
        for S in itertools.combinations(range(n), r):
            mask = sum(1 << x for x in S)
            for j in S:
                others = [i for i in S if i != j]
                dst.append(mask * n + j)
                src.append([(mask ^ (1 << j)) * n + i for i in others])
                ii.append(others)
                jj.append(j)
        out.append(tuple(np.asarray(a, np.int32) for a in (dst, src, ii, jj)))
    return tuple(out)


def shortest_path(q: ArrayLike, dev_pos: ArrayLike, q_fin: ArrayLike) -> jax.Array:
    """(N,) device indices in the order of the shortest open path q -> every device -> q_fin
    (Held-Karp in float32: best[S, j], the shortest path from q through the set S ending at j, is
    the min over i in S \\ j of best[S \\ j, i] + d(i, j)); N <= SHORTEST_MAX_DEVICES."""
    dev_pos = jnp.asarray(dev_pos, jnp.float32)
    n = dev_pos.shape[0]
    if n > SHORTEST_MAX_DEVICES:
        raise ValueError(f"the shortest path is exact up to {SHORTEST_MAX_DEVICES} devices, got N = {n}")
    if n <= 1:
        return jnp.zeros(n, jnp.int32)
    nodes = jnp.concatenate([jnp.asarray(q, jnp.float32)[None], dev_pos, jnp.asarray(q_fin, jnp.float32)[None]])
    D = jnp.linalg.norm(nodes[:, None] - nodes[None], axis=-1)
    d = D[1:-1, 1:-1]
    first = (1 << np.arange(n)) * n + np.arange(n)
    best = jnp.full(((1 << n) * n,), jnp.inf, jnp.float32).at[first].set(D[0, 1:-1])
    parent = jnp.zeros(((1 << n) * n,), jnp.int32)
    for dst, src, ii, jj in _subsets(n):
        cand = best[src] + d[ii, jj[:, None]]
        a = jnp.argmin(cand, axis=-1)
        best = best.at[dst].set(jnp.take_along_axis(cand, a[:, None], -1)[:, 0])
        parent = parent.at[dst].set(jnp.asarray(ii)[np.arange(len(ii)), a])
    full = (1 << n) - 1
    j = jnp.argmin(best[full * n : full * n + n] + D[1:-1, -1]).astype(jnp.int32)
    S, order = jnp.int32(full), []
    for _ in range(n):  # undo the recursion from the last device back
        order.append(j)
        S, j = S ^ (1 << j), parent[S * n + j]
    return jnp.stack(order[::-1]).astype(jnp.int32)


def numbered_order(live: ArrayLike) -> jax.Array:
    """(N,) the live devices in index order, then the others: the tour of a BS that numbered the
    devices along :func:`shortest_path` when the layout was drawn (``EnvState.renumbered``)."""
    return jnp.argsort(~jnp.asarray(live), stable=True).astype(jnp.int32)
