"""The exact receding-horizon planner (baselines/receding.py) and the engine that re-plans it
(semuav_jax.rollout.rollout_replanned)."""

import jax
import numpy as np
import pytest

from baselines import receding
from baselines.evaluate import run
from baselines.planner import make_plans, planner
from baselines.policies import greedy, init_state
from semuav_jax.params import make_params
from semuav_jax.rollout import rollout, rollout_replanned


def test_replanned_engine_equals_rollout_when_nothing_is_replanned(params):
    keys = jax.random.split(jax.random.PRNGKey(2), 8)
    states = jax.vmap(init_state, (None, 0))(18.0, np.tile(np.arange(params.N), (8, 1)))
    want, tr = rollout(greedy, keys, params, states, trace=True)
    calls = []

    def keep(s, ps):
        calls.append(int(np.asarray(s.t).max()))
        return states if ps is None else ps

    got, tr2 = rollout_replanned(greedy, keys, params, keep, every=40, trace=True)
    assert len(calls) == 7 and calls[:6] == list(range(0, 240, 40))  # t freezes once an episode ends
    for k in ("mean_psnr", "coverage", "mission_time", "arrived"):
        np.testing.assert_allclose(np.asarray(got[k]), np.asarray(want[k]), atol=1e-5)
    np.testing.assert_allclose(np.asarray(tr2["q"]), np.asarray(tr["q"]), atol=1e-3)
    with pytest.raises(ValueError, match="every must be an integer number of slots >= 1, got 0"):
        rollout_replanned(greedy, keys, params, keep, every=0)


def test_options_by_hand(params):
    p = params.replace(B=20e3)
    w, after, service, target = receding.options(25.0, np.zeros((1, 1)), p)
    passes = w > 0
    # a pass at the cruise speed costs only the turn booked, TURN_SHARE v / a_max = 0.5 * 25 / 5 s;
    # slower passes cost more and deliver more
    assert service[0, 0, passes][-1] == pytest.approx(receding.TURN_SHARE * 5.0)
    assert np.all(np.diff(service[0, 0, passes]) <= 0) and np.all(np.diff(after[0, 0, passes]) <= 1e-9)
    # stops: more symbols take at least as long; the target is what ends the visit in flight
    stops = ~passes
    assert np.all(np.diff(service[0, 0, stops]) >= 0) and np.all(
        after[0, 0, stops] >= np.minimum(target[0, 0, stops], p.M)
    )
    # a full hover: braking from 25 m/s at 3 m/s^2 and speeding up at 5 m/s^2 cost 25^2/50 (1/3 + 1/5) = 6.67 s
    assert service[0, 0, -1] >= 6.67 and np.all(np.isclose(service * 4, np.round(service * 4)))
    # symbols already received: nothing left to gain from a device that holds M
    full = receding.options(25.0, np.full((1, 1), float(p.M)), p)[1]
    assert np.all(full == p.M)


def test_planned_flights_arrive_and_beat_the_open_loop_plan(params):
    keys = jax.random.split(jax.random.PRNGKey(5), 32)
    p = params.replace(B=25e3)
    m, tr = receding.fly(keys, p, workers=1, trace=True)
    assert m["arrived"].all() and tr["q"].shape == (32, p.K, 2)
    old = np.asarray(run(planner, keys, p, make_plans(keys, p, workers=1))["mean_psnr"])
    assert m["mean_psnr"].mean() > old.mean()
    with pytest.raises(ValueError, match="re-plan interval.*got 0"):
        receding.fly(keys, p, every_s=0.0)
    with pytest.raises(ValueError, match="speeds must be finite and > 0"):
        receding.make_replanner(make_params(params.C), speeds=(float("nan"),))
