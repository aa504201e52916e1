"""Greedy, TSP and straight-flight baselines of MODEL.md section 7 as pure policies.

Each policy is ``policy(policy_state, env_state, params) -> (acceleration (2,), policy_state)``
(the interface of ``semuav_jax.rollout``). The policy state carries the speed v_b (traced, so a
velocity sweep is a ``vmap``), the TSP rank of each device and the set of passed devices.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from baselines.controller import feasible, speed_command
from semuav_jax.params import EnvParams

DEFAULT_V_B = 8.9  # m/s, the paper's baseline speed


@struct.dataclass
class BaselineState:
    """Policy state of one episode: speed v_b, visiting rank (N,) and passed flags (N,)."""

    v_b: jax.Array
    rank: jax.Array
    passed: jax.Array


def init_state(v_b, rank) -> BaselineState:
    """Fresh state for one episode; ``rank[n]`` is device n's position in the TSP order."""
    rank = jnp.asarray(rank, jnp.int32)
    return BaselineState(v_b=jnp.asarray(v_b, jnp.float32), rank=rank, passed=jnp.zeros(rank.shape, bool))


def _follow(score, ps: BaselineState, s, params: EnvParams):
    """Fly to the unpassed feasible device of lowest ``score``, or to q_fin when there is none.

    Targets within v_b tau are marked passed and the choice is repeated, so the UAV never
    circles a device it already reached.
    """
    ok = feasible(s.q, s.t, s.dev_pos, ps.v_b, params)
    dist = jnp.linalg.norm(s.dev_pos - s.q, axis=-1)

    def pick(passed):
        cand = ok & ~passed
        i = jnp.argmin(jnp.where(cand, score, jnp.inf))
        return i, jnp.any(cand)

    def reached(passed):
        i, has = pick(passed)
        return has & (dist[i] <= ps.v_b * params.tau)

    passed = jax.lax.while_loop(reached, lambda p: p.at[pick(p)[0]].set(True), ps.passed)
    i, has = pick(passed)
    target = jnp.where(has, s.dev_pos[i], params.q_fin)
    return speed_command(s.q, s.v, target, ps.v_b, params), ps.replace(passed=passed)


def greedy(ps: BaselineState, s, params: EnvParams):
    """Greedy: nearest unpassed feasible device, then q_fin."""
    return _follow(jnp.linalg.norm(s.dev_pos - s.q, axis=-1), ps, s, params)


def tsp(ps: BaselineState, s, params: EnvParams):
    """TSP: devices in the precomputed order ``ps.rank``, skipping infeasible ones, then q_fin."""
    return _follow(ps.rank.astype(jnp.float32), ps, s, params)


def straight(ps: BaselineState, s, params: EnvParams):
    """Floor: straight flight from q0 to q_fin at v_b, serving whatever lies on the way."""
    return speed_command(s.q, s.v, params.q_fin, ps.v_b, params), ps


POLICIES = {"greedy": greedy, "tsp": tsp, "straight": straight}
