"""Greedy, TSP and straight-flight baselines of MODEL.md section 7 as pure policies.

Each policy is ``policy(policy_state, env_state, params) -> (acceleration (2,), policy_state)``
(the interface of ``semuav_jax.rollout``). The policy state carries the speed v_b (traced, so a
velocity sweep is a ``vmap``), the TSP rank of each device and the set of passed devices.
All of them steer with the core controller (``semuav_jax.control``, docs/model.md eqs. 7.1-7.5):

- a device is feasible when flying through it and then home fits in the time left (eq. 7.6);
- the current target device is passed once its horizontal distance is <= v_b tau;
- with no feasible device left, the UAV flies home and brakes into the arrival disk (eq. 7.3).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
from flax import struct
from jax.typing import ArrayLike

from semuav_jax.control import home_command, speed_command, time_via
from semuav_jax.params import EnvParams

if TYPE_CHECKING:
    from semuav_jax.env import EnvState

DEFAULT_V_B = 8.9  # m/s, the paper's baseline speed
MARGIN_S = (
    1.0  # seconds of slack in the feasibility test (eq. 7.6); 0 still arrived in 1000 of 1000 layouts at every v_b
)


def feasible(
    q: jax.Array, v: jax.Array, t: jax.Array, dev_pos: jax.Array, v_b: jax.Array, params: EnvParams
) -> jax.Array:
    """(N,) bool, eq. 7.6: flying from (q, v) through p_n at v_b (eq. 7.4) and from there home
    (eq. 7.5, leaving p_n at v_b along the approach course) fits in the time left (K - t) tau
    less ``MARGIN_S``."""
    need = jax.vmap(lambda p: time_via(q, v, p, v_b, params))(dev_pos)
    return need + MARGIN_S <= (params.K - t) * params.tau


@struct.dataclass
class BaselineState:
    """Policy state of one episode: speed v_b, visiting rank (N,) and passed flags (N,)."""

    v_b: jax.Array
    rank: jax.Array
    passed: jax.Array


def init_state(v_b: ArrayLike, rank: jax.Array) -> BaselineState:
    """Fresh state for one episode; ``rank[n]`` is device n's position in the TSP order."""
    rank = jnp.asarray(rank, jnp.int32)
    return BaselineState(v_b=jnp.asarray(v_b, jnp.float32), rank=rank, passed=jnp.zeros(rank.shape, bool))


def _follow(score: jax.Array, ps: BaselineState, s: EnvState, params: EnvParams) -> tuple[jax.Array, BaselineState]:
    """Fly to the unpassed feasible device of lowest ``score``, or to q_fin when there is none.

    Targets within v_b tau are marked passed and the choice is repeated, so the UAV never
    circles a device it already reached.
    """
    ok = feasible(s.q, s.v, s.t, s.dev_pos, ps.v_b, params)
    dist = jnp.linalg.norm(s.dev_pos - s.q, axis=-1)

    def pick(passed: jax.Array) -> tuple[jax.Array, jax.Array]:
        cand = ok & ~passed
        i = jnp.argmin(jnp.where(cand, score, jnp.inf))
        return i, jnp.any(cand)

    def reached(passed: jax.Array) -> jax.Array:
        i, has = pick(passed)
        return has & (dist[i] <= ps.v_b * params.tau)

    passed = jax.lax.while_loop(reached, lambda p: p.at[pick(p)[0]].set(True), ps.passed)
    i, has = pick(passed)
    a = jnp.where(has, speed_command(s.q, s.v, s.dev_pos[i], ps.v_b, params), home_command(s.q, s.v, ps.v_b, params))
    return a, ps.replace(passed=passed)


def greedy(ps: BaselineState, s: EnvState, params: EnvParams) -> tuple[jax.Array, BaselineState]:
    """Greedy: nearest unpassed feasible device, then q_fin."""
    return _follow(jnp.linalg.norm(s.dev_pos - s.q, axis=-1), ps, s, params)


def tsp(ps: BaselineState, s: EnvState, params: EnvParams) -> tuple[jax.Array, BaselineState]:
    """TSP: devices in the precomputed order ``ps.rank``, skipping infeasible ones, then q_fin."""
    return _follow(ps.rank.astype(jnp.float32), ps, s, params)


def straight(ps: BaselineState, s: EnvState, params: EnvParams) -> tuple[jax.Array, BaselineState]:
    """Floor: straight flight from q0 to q_fin at v_b, serving whatever lies on the way."""
    return home_command(s.q, s.v, ps.v_b, params), ps


POLICIES = {"greedy": greedy, "tsp": tsp, "straight": straight}
