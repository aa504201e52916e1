"""Dwell-switch: the dwell rules of ``baselines/dwell.py`` with their knobs chosen during the flight
by simulation at the BS (docs/model.md eq. 7.15, ``semuav_jax.lookahead``): every ``SWITCH_EVERY``
slots the BS simulates greedy-dwell and TSP-dwell at each k* of ``SWITCH_K`` (v_c and the margin
of the tuned rules) from the current state to the end of the mission, with fresh delay draws, and
follows the best until the next decision. In expectation it is never below the best of these rules
followed throughout, since that rule is one of its candidates at every decision."""

from __future__ import annotations

from functools import cache
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from baselines.dwell import DwellState, check_knobs, dwell_command, init_dwell
from semuav_jax.engine import Policy
from semuav_jax.lookahead import Switching, rollout_switching

if TYPE_CHECKING:
    from semuav_jax.env import EnvState
    from semuav_jax.params import EnvParams

SWITCH_K = (16.0, 32.0, 48.0, 64.0, 96.0, 128.0)  # symbols: the k* each order is simulated with
SWITCH_EVERY = 16  # slots (8 s) between two decisions
SWITCH_SAMPLES = 1  # delay draws per candidate and decision


def either_dwell(ps: tuple[jax.Array, DwellState], s: EnvState, params: EnvParams) -> tuple[jax.Array, tuple]:
    """Greedy-dwell when ``ps[0]`` is True, else TSP-dwell (eq. 7.10), at the knobs of ``ps[1]``."""
    greedy, d = ps
    score = jnp.where(greedy, jnp.linalg.norm(s.dev_pos - s.q, axis=-1), d.rank.astype(jnp.float32))
    return dwell_command(score, d, s, params), ps


def knob_table(v_c: float, margin: float, k_star: ArrayLike = SWITCH_K) -> jax.Array:
    """(C, 4) candidates: (greedy?, v_c, k*, margin), greedy-dwell's then TSP-dwell's."""
    ks = np.atleast_1d(np.asarray(k_star, np.float32))
    rows = [(g, v_c, k, margin) for g in (1.0, 0.0) for k in ks]
    return jnp.asarray(rows, jnp.float32)


def dwell_candidate(
    table: jax.Array, rank: jax.Array, c: jax.Array, now: Any = None, state: Any = None, params: Any = None
) -> tuple[jax.Array, DwellState]:
    """The policy state of :func:`either_dwell` for row ``c`` of :func:`knob_table` (the policy and
    env state at the decision, ``now`` and ``state``, are not needed)."""
    row = table[c]
    return row[0] > 0, init_dwell(row[1], row[2], row[3], rank)


@cache
def switching(every: int = SWITCH_EVERY, samples: int = SWITCH_SAMPLES, count: int = 2 * len(SWITCH_K)) -> Switching:
    return Switching(Policy(act=either_dwell), dwell_candidate, count, every, samples)


def dwell_switch_metrics(
    keys: jax.Array,
    params: EnvParams,
    v_c: float,
    margin: float,
    rank: ArrayLike,
    k_star: ArrayLike = SWITCH_K,
    every: int = SWITCH_EVERY,
    samples: int = SWITCH_SAMPLES,
    trace: bool = False,
) -> tuple[dict[str, jax.Array], jax.Array, dict[str, jax.Array] | None]:
    """Per-episode metrics, (E, decisions) chosen candidates (rows of :func:`knob_table`) and, with
    ``trace``, the flights' trace (``lookahead.rollout_switching``)."""
    check_knobs(v_c, k_star, margin, params)
    table = knob_table(v_c, margin, k_star)
    sw = switching(every, samples, int(table.shape[0]))
    return rollout_switching(sw, keys, params, table, jnp.asarray(rank, jnp.int32), trace)
