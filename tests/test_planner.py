"""The offline planner (baselines/planner.py, docs/baselines.md "Planner"): its time and symbol
models by hand, and its flights in the env."""

import jax
import numpy as np
import pytest

from baselines import orienteering
from baselines.evaluate import evaluate, layouts, run
from baselines.planner import PLAN_SLACK_S, hover_rate, make_plans, planner, problems, visit_options
from semuav_jax.params import make_params


def test_travel_by_hand(params):
    # one device at (500, 300), cruise 20 m/s: q0 -> device 500 / 20 + 0.5 (delay) + 20 / 10 (speeding up);
    # device -> q_fin 500 / 20 + 0.5 + 20 / (2 * 0.25 * 5) (braking into the disk) - 15 / 20
    pos, img = np.array([[[500.0, 300.0]]]), np.array([[0]])
    travel = problems(pos, img, params, 20.0)[0][0]
    assert travel[0, 1] == pytest.approx(25 + 0.5 + 2.0)
    assert travel[1, 2] == pytest.approx(25 + 0.5 + 8.0 - 0.75)
    assert travel[0, 2] == pytest.approx(50 + 0.5 + 2.0 + 8.0 - 0.75)


def test_hover_rate_is_the_model_check(curves):
    # MODEL.md section 2: 324.7 bit/s right below the UAV at 20 kHz, / 16 bit per symbol
    assert hover_rate(make_params(curves)) == pytest.approx(324.7 / 16, rel=1e-3)


def test_visit_options_are_ordered(params):
    w, sym, service, target = visit_options(20.0, params)
    passes = w > 0
    # slower passes take longer and receive more; every option is on the 0.25 s grid
    assert (
        np.all(np.diff(service[passes]) <= 0) and np.all(np.diff(sym[passes]) <= 0) and service[0] > service[passes][-1]
    )
    assert np.all(sym <= params.M) and np.allclose(service * 4, np.round(service * 4))
    assert np.all(target[passes] == params.M) and np.all(target[~passes] == sym[~passes])


def test_plans_fit_the_budget_and_fly_home(params):
    keys = jax.random.split(jax.random.PRNGKey(5), 64)
    p = params.replace(B=25e3)
    plans = make_plans(keys, p, workers=1)
    order = np.asarray(plans.order)
    assert np.all((order >= -1) & (order < p.N)) and np.all(np.asarray(plans.idx) == 0)
    # the chosen plan of each layout fits T + PLAN_SLACK_S under the plan's own time model
    pos, img = (np.asarray(x) for x in layouts(keys, p))
    for e in range(4):
        travel, service, prize, w, target = problems(
            pos[e : e + 1].astype(float), img[e : e + 1], p, float(plans.v_p[e])
        )
        o = orienteering.solve(travel[0], service[0], prize[0], 125.0 + PLAN_SLACK_S)
        np.testing.assert_array_equal(o[0], order[e])
    m = {k: np.asarray(v) for k, v in run(planner, keys, p, plans).items()}
    assert m["arrived"].all()
    # it beats the paper's greedy at 8.9 m/s on the same episodes
    assert m["mean_psnr"].mean() > evaluate("greedy", keys, p)["mean_psnr"].mean() + 1.0


def test_planner_stays_in_the_airspace(params):
    keys = jax.random.split(jax.random.PRNGKey(6), 64)
    p = params.replace(B=25e3, airspace_margin=0.0)
    m = {k: np.asarray(v) for k, v in run(planner, keys, p, make_plans(keys, p, workers=1)).items()}
    assert m["arrived"].all()


def test_bad_speeds():
    p = make_params()
    keys = jax.random.split(jax.random.PRNGKey(0), 2)
    with pytest.raises(ValueError, match="planner speeds must be finite and > 0"):
        make_plans(keys, p, speeds=(0.0,))
    for bad in (0.0, -3.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="v_b must be finite and > 0 m/s"):
            evaluate("greedy", keys, p, v_b=bad)
