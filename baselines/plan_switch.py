"""Plan-switch: the exact receding-horizon planner with every re-plan checked by simulation against
the dwell rules (docs/model.md eq. 7.16, docs/baselines.md "Plan-switch").

At each re-plan (``receding.REPLAN_EVERY_S``) the BS solves the exact plan from the current state
(``receding.make_replanner``), then simulates, from that state to the end of the mission with fresh
delay draws, C = 1 + 12 candidates: the new plan followed open loop, and greedy-dwell and TSP-dwell at
each k* of ``dwell_switch.SWITCH_K`` (eq. 7.15's candidates); it flies the best until the next
re-plan. So each decision is never worse in expectation than the plan alone or any dwell rule from
that state, which the exact planner and dwell-switch each are on their own.
"""

from __future__ import annotations

import itertools
from functools import cache, partial
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct
from jax.typing import ArrayLike

from baselines import receding
from baselines.dwell import DwellState, check_knobs
from baselines.dwell_switch import SWITCH_K, SWITCH_SAMPLES, dwell_candidate, either_dwell, knob_table
from baselines.planner import PlanState, planner
from semuav_jax.engine import Policy
from semuav_jax.lookahead import Switching, choose, decision_key
from semuav_jax.params import EnvParams, validate_params
from semuav_jax.rollout import rollout_replanned

if TYPE_CHECKING:
    from semuav_jax.env import EnvState


@struct.dataclass
class HybridState:
    """Policy state: fly the plan (``use_plan``) or the dwell rule ``dwell`` = (greedy?, knobs)."""

    use_plan: jax.Array
    plan: PlanState
    dwell: tuple[jax.Array, DwellState]


def hybrid(ps: HybridState, s: EnvState, params: EnvParams) -> tuple[jax.Array, HybridState]:
    """The planner's command when ``ps.use_plan``, else the dwell rule's (both advance their state)."""
    a_plan, plan = planner(ps.plan, s, params)
    a_dwell, _ = either_dwell(ps.dwell, s, params)
    return jnp.where(ps.use_plan, a_plan, a_dwell), ps.replace(plan=plan)


def hybrid_candidate(
    table: jax.Array,
    per_episode: tuple[PlanState, jax.Array],
    c: jax.Array,
    now: Any = None,
    state: Any = None,
    params: Any = None,
) -> HybridState:
    """Candidate 0: the plan; candidate c >= 1: row c - 1 of ``dwell_switch.knob_table`` (``now``,
    ``state`` unused)."""
    plan, rank = per_episode
    return HybridState(c == 0, plan, dwell_candidate(table, rank, jnp.maximum(c - 1, 0)))


@cache
def plan_switching(count: int, samples: int = SWITCH_SAMPLES) -> Switching:
    """The candidates' simulation (``every`` is unused: ``rollout_replanned`` sets the decisions)."""
    return Switching(Policy(act=hybrid), hybrid_candidate, count, 1, samples)


@partial(jax.jit, static_argnames=("sw",))
def _choose_all(
    sw: Switching, states: EnvState, table: jax.Array, per_episode: Any, keys: jax.Array, params: EnvParams, t: int
) -> jax.Array:
    """The candidate every episode chooses at its decision at slot ``t`` (every episode's)."""
    return jax.vmap(lambda s, pe, k: choose(sw, s, table, pe, k, params, t=t)[0])(states, per_episode, keys)


def fly(
    keys: jax.Array,
    params: EnvParams,
    v_c: float,
    margin: float,
    rank: ArrayLike,
    k_star: ArrayLike = SWITCH_K,
    workers: int = 2,
    trace: bool = False,
) -> tuple[dict[str, np.ndarray], np.ndarray, dict[str, jax.Array] | None]:
    """Plan-switch on the episodes ``keys`` (the layouts and delays of ``rollout``), dwell candidates
    at cruise speed ``v_c`` and ``margin`` with TSP ranks ``rank`` (E, N): (NumPy (E,) metrics,
    (E, decisions) chosen candidates (0: the plan), the trace when asked)."""
    validate_params(params)
    check_knobs(v_c, k_star, margin, params)
    table = knob_table(v_c, margin, k_star)
    sw = plan_switching(1 + int(table.shape[0]))
    rank = jnp.asarray(rank, jnp.int32)
    keys = jnp.asarray(keys)
    exact, calls, chosen = receding.make_replanner(params, workers=workers), itertools.count(), []

    def replan(states: EnvState, ps: HybridState | None) -> HybridState:
        plan = jax.tree.map(jnp.asarray, exact(states, None if ps is None else ps.plan))
        i = next(calls)
        best = _choose_all(
            sw, states, table, (plan, rank), jax.vmap(decision_key, (0, None))(keys, i), params, i * every
        )
        chosen.append(np.asarray(best))
        return jax.vmap(hybrid_candidate, (None, 0, 0))(table, (plan, rank), best)

    every = max(1, round(receding.REPLAN_EVERY_S / float(params.tau)))
    m, tr = rollout_replanned(Policy(act=hybrid), keys, params, replan, every, trace)
    return jax.tree.map(np.asarray, m), np.stack(chosen, axis=1), tr
