"""Plan-switch (baselines/plan_switch.py, docs/model.md eq. 7.16): the exact planner's re-plans
checked against the dwell rules by simulation."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from baselines import plan_switch, receding, tsp_ranks
from baselines.dwell_switch import either_dwell, knob_table
from baselines.planner import make_plans, planner
from semuav_jax.env import reset_state
from semuav_jax.params import make_params


@pytest.fixture(scope="module")
def p():
    return make_params(B=5e3)


@pytest.fixture(scope="module")
def keys():
    return jax.random.split(jax.random.PRNGKey(5), 4)


def test_a_candidate_flies_the_plan_or_its_dwell_rule(p, keys):
    """Candidate 0 sends the planner's command, candidate c >= 1 that of row c - 1 of the knob table."""
    s = reset_state(keys[0], p)
    plan = jax.tree.map(lambda x: x[0], make_plans(keys[:1], p, workers=1))
    table, rank = knob_table(25.0, -2.0), jnp.arange(10, dtype=jnp.int32)
    for c in (0, 1, 7, 12):
        ps = plan_switch.hybrid_candidate(table, (plan, rank), jnp.int32(c))
        a, _ = plan_switch.hybrid(ps, s, p)
        want = planner(plan, s, p)[0] if c == 0 else either_dwell(ps.dwell, s, p)[0]
        np.testing.assert_array_equal(np.asarray(a), np.asarray(want))
        assert bool(ps.use_plan) == (c == 0)
    np.testing.assert_array_equal(
        np.asarray(plan_switch.hybrid_candidate(table, (plan, rank), 3).dwell[1].k_star), 48.0
    )


def test_deterministic_arrives_and_records_its_choices(p, keys):
    rank = tsp_ranks(keys, p, workers=1)
    a, ca, tr = plan_switch.fly(keys, p, 25.0, -2.0, rank, workers=1, trace=True)
    b, cb, _ = plan_switch.fly(keys, p, 25.0, -2.0, rank, workers=1)
    np.testing.assert_array_equal(a["mean_psnr"], b["mean_psnr"])
    np.testing.assert_array_equal(ca, cb)
    every = round(receding.REPLAN_EVERY_S / float(p.tau))
    assert ca.shape == (len(keys), -(-p.K // every)) and ca.min() >= 0 and ca.max() <= 12
    assert tr["q"].shape == (len(keys), p.K, 2)
    assert np.all(a["arrived"]) and np.all(np.isfinite(a["mean_psnr"]))


def test_bad_knobs_are_one_line_errors(p, keys):
    with pytest.raises(ValueError, match="v_c"):
        plan_switch.fly(keys, p, -1.0, 0.0, np.zeros((len(keys), 10), np.int32), workers=1)
