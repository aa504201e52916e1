"""A short open path through the unfinished devices (docs/model.md eq. 6.5): nearest neighbour from
the UAV, then local search with both ends fixed (the best 2-opt reversal or single-device
relocation, TOUR_MOVES times), in JAX so the BS can re-plan it at every decision inside
``jit``/``vmap``. ``benchmarks/tour.py`` measures it against Held-Karp."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

TOUR_MOVES = 4  # improving moves per plan


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
