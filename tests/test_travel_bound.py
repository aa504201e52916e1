"""The certified bound (baselines/travel_bound.py, docs/baselines.md eqs. 7.12-7.14): dead slots
and envelopes by hand, the bisection against a brute-force water-filling, and that no policy of
ours exceeds it on any layout."""

import jax
import numpy as np
import pytest

from baselines import plan_switch, receding
from baselines.bound import peak_rate, psnr_bound
from baselines.dwell import dwell_metrics, greedy_dwell, tsp_dwell
from baselines.dwell_switch import dwell_switch_metrics
from baselines.evaluate import evaluate, run, tsp_ranks
from baselines.planner import make_plans, planner
from baselines.travel_bound import _subsets, dead_slots, envelope_gains, flight_account, layout_bound, travel_bound
from semuav_jax.params import make_params
from semuav_jax.rollout import random_policy, random_policy_state, rollout


def test_dead_slots_by_hand(params):
    # one device at (500, 300): r_c = sqrt(105^2 - 100^2) = 32.02 m, v_max tau = 12.5 m per slot
    rc = np.sqrt(105.0**2 - 100.0**2)
    dead = dead_slots(np.array([[[500.0, 300.0]]]), params)[0]
    assert dead[0] == pytest.approx((1000.0 - 15.0) / 12.5 - 1.0)  # no disc touched: q0 straight home
    assert dead[1] == pytest.approx((500.0 - rc) / 12.5 - 1.0 + (500.0 - rc - 15.0) / 12.5 - 1.0)
    # two devices: the tree joins q0 to the nearer disc and the discs by their gap, not a path
    pos = np.array([[[100.0, 300.0], [100.0, 500.0]]])
    d = dead_slots(pos, params)[0]
    to_first, gap = (100.0 - rc) / 12.5 - 1.0, (200.0 - 2 * rc) / 12.5 - 1.0
    home = np.hypot(900.0, 0.0) - rc - 15.0
    assert d[0b11] == pytest.approx(to_first + gap + home / 12.5 - 1.0)


def test_unused_time_in_reach_of_an_unserved_device(params):
    """A flight that ends after 40 of K slots touching no device leaves T - 20 s unused, all of it
    with some device in reach (every device lies well within (T - 20 s) * v_max / 2 of q_fin); one
    that touched every device, or that used the whole mission, leaves none in reach."""
    keys = jax.random.split(jax.random.PRNGKey(4), 1)
    K, N, tau = params.K, params.N, float(params.tau)
    done = np.zeros((1, K), bool)
    done[0, 39:] = True
    trace = {"x": np.zeros((1, K, N), bool), "done": done, "m": np.zeros((1, K, N))}
    a = flight_account(trace, keys, params)
    assert a["unused_s"][0] == pytest.approx((K - 40) * tau)
    assert a["unused_in_reach_s"][0] == pytest.approx((K - 40) * tau)
    touched = dict(trace, x=np.ones((1, K, N), bool))
    assert flight_account(touched, keys, params)["unused_in_reach_s"][0] == 0.0
    whole = dict(trace, done=np.zeros((1, K), bool))
    assert flight_account(whole, keys, params)["unused_in_reach_s"][0] == 0.0


def test_envelope_gains_are_a_concave_majorant(curves):
    C = np.asarray(make_params().C, np.float64)  # the DeepJSCC curves: not concave, not monotone
    g = envelope_gains(C)
    assert np.all(np.diff(g, axis=1) <= 1e-9)
    env = C[:, :1] + np.concatenate([np.zeros((len(C), 1)), np.cumsum(g, axis=1)], axis=1)
    assert np.all(env >= np.maximum.accumulate(C, axis=1) - 1e-9)
    np.testing.assert_allclose(env[:, -1], C.max(axis=1), atol=1e-9)


def test_bisection_equals_brute_force_water_filling(params):
    rng = np.random.default_rng(0)
    for n, M in ((3, 5), (4, 8)):
        gains = -np.sort(-rng.exponential(size=(n, M)).round(1), axis=1)  # ties on purpose
        base = rng.normal(size=n)
        dead = rng.uniform(params.K - 3 * M / 2, params.K, size=1 << n)
        s0 = peak_rate(params) * float(params.tau) / float(params.beta)
        budget = np.floor(np.maximum(params.K - dead, 0.0) * s0 * (1 + 1e-5)).astype(int)
        want = -np.inf
        for S in range(1 << n):
            units = sorted((x for j in range(n) if S >> j & 1 for x in gains[j]), reverse=True)
            want = max(want, sum(units[: budget[S]]))
        assert layout_bound(dead, gains, base, params) == pytest.approx((base.sum() + want) / n)
    assert _subsets(3)[0b101].tolist() == [1, 0, 1]


@pytest.mark.slow
@pytest.mark.parametrize("B", [5e3, 25e3])
def test_no_policy_of_ours_exceeds_it(B):
    p = make_params(B=B)
    keys = jax.random.split(jax.random.PRNGKey(11), 48)
    bound = np.minimum(travel_bound(keys, p), psnr_bound(keys, p))
    rank = tsp_ranks(keys, p, workers=1)
    got = [evaluate(n, keys, p, v_b=v, rank=rank)["mean_psnr"] for n in ("greedy", "tsp") for v in (8.9, 18.0, 25.0)]
    got += [
        np.asarray(dwell_metrics(f, keys, p, v, k, 0.0, rank)["mean_psnr"])
        for f in (greedy_dwell, tsp_dwell)
        for v, k in ((25.0, 16.0), (25.0, 256.0), (18.0, 64.0))
    ]
    got.append(np.asarray(run(planner, keys, p, make_plans(keys, p, workers=1))["mean_psnr"]))
    got.append(receding.fly(keys, p, workers=1)[0]["mean_psnr"])
    got.append(np.asarray(dwell_switch_metrics(keys, p, 25.0, -2.0, rank)[0]["mean_psnr"]))
    got.append(plan_switch.fly(keys, p, 25.0, -2.0, rank, workers=1)[0]["mean_psnr"])
    draws = jax.vmap(random_policy_state, (0, None))(jax.random.split(jax.random.PRNGKey(1), 48), p)
    got.append(np.asarray(rollout(random_policy, keys, p, policy_state=draws)[0]["mean_psnr"]))
    assert np.all(np.stack(got) <= bound)
    assert np.all(travel_bound(keys, p) <= psnr_bound(keys, p) + 0.6)  # never much looser than the budget bound
