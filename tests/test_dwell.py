"""Greedy-dwell and TSP-dwell (baselines/dwell.py, docs/baselines.md eqs. 7.9-7.10): stops and
leaves by hand on a one-device layout, the grid against a plain loop, bad knobs."""

import jax
import numpy as np
import pytest

from baselines.dwell import (
    DWELL_POLICIES,
    candidates,
    check_knobs,
    dwell_metrics,
    dwell_sweep,
    greedy_dwell,
    init_dwell,
)
from baselines.evaluate import tsp_ranks
from semuav_jax.env import initial_state
from semuav_jax.params import make_params
from semuav_jax.rollout import rollout


@pytest.fixture(scope="module")
def one(curves):
    # one device on the straight route q0 -> q_fin, 25 kHz (about 25 symbols/s right below the UAV)
    return make_params(curves, N=1, device_pos=[[500.0, 300.0]], device_img=[0], layout="fixed", B=25e3)


def _flight(p, k_star, margin=0.0):
    keys = jax.random.split(jax.random.PRNGKey(0), 1)
    ps = jax.vmap(init_dwell, (None, None, None, 0))(25.0, k_star, margin, np.zeros((1, 1), np.int32))
    return rollout(greedy_dwell, keys, p, ps, trace=True)


def test_it_stops_over_the_device_until_k_symbols_then_leaves(one):
    m, tr = _flight(one, 128.0)
    speed = np.linalg.norm(np.asarray(tr["v"][0]), axis=-1)
    dist = np.linalg.norm(np.asarray(tr["q"][0]) - np.array([500.0, 300.0]), axis=-1)
    sym = np.asarray(tr["m"][0, :, 0])
    t_k = int(np.argmax(sym >= 128.0))  # the slot where k* is reached
    assert speed[:t_k].min() < 1.0 and dist[np.argmin(speed[:t_k])] < 5.0  # it came to rest over the device
    assert speed[t_k + 12] > 10.0  # and left once k* symbols had arrived
    assert sym[-1] >= 128.0
    assert bool(m["arrived"][0])
    # a pass at 25 m/s (k* already met on the way in) never slows down below 10 m/s
    _, tr8 = _flight(one, 8.0)
    assert np.linalg.norm(np.asarray(tr8["v"][0]), axis=-1)[20:80].min() > 10.0


def test_leaving_is_required_to_arrive(one):
    # at 1 kHz (about 1 symbol/s) k* = M is out of reach: the time test sends it home, and it arrives
    m, tr = _flight(one.replace(B=1e3), float(one.M))
    assert bool(m["arrived"][0]) and float(m["mission_time"][0]) > 110.0
    assert np.asarray(tr["m"][0, -1, 0]) < one.M


def test_candidates_by_hand(one):
    s = initial_state(one.device_pos, one.device_img, one)
    ps = init_dwell(25.0, 64.0, 0.0, [0])
    assert bool(candidates(ps, s, one)[0])
    assert not bool(candidates(ps, s.replace(m=s.m + 64.0), one)[0])  # k* delivered
    assert not bool(candidates(ps, s.replace(t=s.t + 200), one)[0])  # 25 s left: no time to go there and home
    assert not bool(candidates(ps.replace(margin=ps.margin + 90.0), s, one)[0])


def test_sweep_equals_a_plain_loop(params):
    keys = jax.random.split(jax.random.PRNGKey(3), 16)
    p = params.replace(B=20e3)
    rank = tsp_ranks(keys, p, workers=1)
    grid = ([20.0, 25.0], [16.0, 64.0], [0.0, 2.0])
    for name, policy in DWELL_POLICIES.items():
        m = dwell_sweep(name, keys, p, *grid, B=[20e3, 5e3], rank=rank)
        assert m["mean_psnr"].shape == (2, 8, 16)
        i = 0
        for v in grid[0]:
            for k in grid[1]:
                for mg in grid[2]:
                    for j, b in enumerate((20e3, 5e3)):
                        want = dwell_metrics(policy, keys, p.replace(B=b), v, k, mg, rank)["mean_psnr"]
                        np.testing.assert_allclose(m["mean_psnr"][j, i], np.asarray(want), atol=1e-4)
                    i += 1
        assert m["arrived"].all()


@pytest.mark.parametrize(
    "v_c,k,margin,match",
    [
        (0.0, 32, 0, "v_c must be finite and > 0"),
        (float("nan"), 32, 0, "v_c"),
        (25, 0, 0, "k_star must be in"),
        (25, 257, 0, r"k_star must be in \(0, M = 256\], got 257"),
        (25, -4, 0, "got -4"),
        (25, 32, float("inf"), "margin must be finite"),
        (25, [[1, 2]], 0, "1-D list"),
    ],
)
def test_bad_knobs_are_one_line_errors(params, v_c, k, margin, match):
    with pytest.raises(ValueError, match=match):
        check_knobs(v_c, k, margin, params)


def test_unknown_dwell_baseline(params):
    with pytest.raises(ValueError, match="unknown dwell baseline 'nearest'"):
        dwell_sweep("nearest", jax.random.split(jax.random.PRNGKey(0), 2), params, 25, 32, 0, [20e3], np.zeros((2, 10)))
