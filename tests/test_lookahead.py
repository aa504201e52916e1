"""Decisions by simulation (semuav_jax/lookahead.py, docs/model.md eq. 7.15) and dwell-switch
(baselines/dwell_switch.py): one candidate is the plain rollout, the choice is the best simulated
candidate, forced actions by hand, bad settings."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from baselines.dwell import greedy_dwell, init_dwell, tsp_dwell
from baselines.dwell_switch import dwell_switch_metrics, either_dwell, knob_table, switching
from semuav_jax.engine import Policy, command
from semuav_jax.env import reset_state
from semuav_jax.lookahead import Forced, Switching, choose, forced, rollout_switching, score
from semuav_jax.params import make_params
from semuav_jax.rollout import episode, rollout


@pytest.fixture(scope="module")
def p(curves):
    return make_params(curves, B=25e3)


@pytest.fixture(scope="module")
def keys():
    return jax.random.split(jax.random.PRNGKey(3), 6)


RANK = np.tile(np.arange(10, dtype=np.int32), (6, 1))


def test_one_candidate_is_the_plain_rollout(p, keys):
    """A single candidate (TSP-dwell at fixed knobs) followed throughout: the episodes of rollout,
    slot for slot (K = 250 is not a multiple of the 16-slot decision period)."""
    table = knob_table(25.0, -2.0, [48.0])[1:]  # the TSP-dwell row only
    m, chosen, tr = rollout_switching(switching(16, 1, 1), keys, p, table, jnp.asarray(RANK), trace=True)
    states = jax.vmap(init_dwell, (None, None, None, 0))(25.0, 48.0, -2.0, RANK)
    ref, ref_tr = rollout(tsp_dwell, keys, p, states, trace=True)
    for k in ("mean_psnr", "arrived", "mission_time", "coverage"):
        np.testing.assert_allclose(np.asarray(m[k]), np.asarray(ref[k]), rtol=1e-6, err_msg=k)
    assert np.all(np.asarray(chosen) == 0)
    assert jax.tree.map(np.shape, tr) == jax.tree.map(np.shape, ref_tr)
    for k in ("q", "m", "done"):
        np.testing.assert_allclose(np.asarray(tr[k]), np.asarray(ref_tr[k]), rtol=1e-6, atol=1e-4, err_msg=k)


def test_either_dwell_is_greedy_or_tsp_dwell(p):
    s = reset_state(jax.random.PRNGKey(1), p)
    d = init_dwell(25.0, 32.0, 0.0, np.arange(10)[::-1].copy())
    for flag, rule in ((True, greedy_dwell), (False, tsp_dwell)):
        np.testing.assert_array_equal(either_dwell((jnp.asarray(flag), d), s, p)[0], rule(d, s, p)[0])


def test_the_choice_is_the_best_simulated_candidate(p):
    """choose() returns the argmax of the candidates' scores, each the mean over the same delay
    draws of an episode simulated from the state."""
    sw = switching(16, 2, 12)
    table, rank = knob_table(25.0, -2.0), jnp.arange(10, dtype=jnp.int32)
    s = reset_state(jax.random.PRNGKey(2), p)
    key = jax.random.PRNGKey(9)
    best, values = choose(sw, s, table, rank, key, p)
    by_hand = []
    for c in range(12):
        ps = sw.candidate(table, rank, jnp.int32(c))
        runs = [episode(sw.policy, k, p, ps, init_state=s)[0] for k in jax.random.split(key, 2)]
        by_hand.append(np.mean([float(score(r, p)) for r in runs]))
    np.testing.assert_allclose(np.asarray(values), by_hand, rtol=1e-5)
    assert int(best) == int(np.argmax(by_hand))


def test_simulating_the_slots_left_chooses_the_same_by_the_same_scores(p):
    """choose(t=...) simulates only the K - t slots left from a state at slot t: the same scores
    bit for bit as simulating K slots (the slots after the end are frozen)."""
    sw = switching(16, 2, 12)
    table, rank = knob_table(25.0, -2.0), jnp.arange(10, dtype=jnp.int32)
    s = reset_state(jax.random.PRNGKey(2), p).replace(t=jnp.int32(101))
    key = jax.random.PRNGKey(9)
    best, values = choose(sw, s, table, rank, key, p)
    best_left, values_left = jax.jit(lambda t: choose(sw, s, table, rank, key, p, t=t))(101)
    np.testing.assert_array_equal(values_left, values)
    assert int(best_left) == int(best)
    assert len(set(np.asarray(values).round(3).tolist())) > 1  # candidates that differ: a real choice


def test_score_puts_arrival_with_slack_first(p):
    T = p.K * p.tau
    m = {k: jnp.asarray(v) for k, v in {"mean_psnr": [30.0, 20.0, 25.0], "arrived": [False, True, True]}.items()}
    m["mission_time"] = jnp.asarray([T, T, T - 5.0])
    assert np.argsort(np.asarray(score(m, p))).tolist() == [0, 1, 2]  # 30 dB late < 20 dB just in time < 25 dB


def test_forced_sends_its_action_for_n_slots_then_the_policy(p):
    zero = Policy(act=lambda ps, s, params: (jnp.zeros(2), ps))
    pol = forced(zero)
    s = reset_state(jax.random.PRNGKey(0), p)
    ps = Forced(None, jnp.asarray([1.0, -1.0]), jnp.asarray(2))
    sent = []
    for _ in range(4):
        a, _, _, ps = command(pol, ps, None, s, p)
        sent.append(np.asarray(a).tolist())
    assert sent == [[1.0, -1.0], [1.0, -1.0], [0.0, 0.0], [0.0, 0.0]]
    assert forced(zero) is pol  # cached: one compiled program per base policy


@pytest.mark.parametrize(
    "change, msg",
    [
        ({"count": 0}, "count must be an integer >= 1"),
        ({"every": 2.5}, "every must be"),
        ({"samples": True}, "samples"),
    ],
)
def test_bad_settings_are_one_line_errors(p, keys, change, msg):
    sw = switching(16, 1, 12)._replace(**change)
    with pytest.raises(ValueError, match=msg):
        rollout_switching(sw, keys, p, knob_table(25.0, 0.0), jnp.asarray(RANK))


def test_dwell_switch_is_deterministic_and_checks_its_knobs(p, keys):
    a, ca, _ = dwell_switch_metrics(keys, p, 25.0, 0.0, RANK)
    b, cb, _ = dwell_switch_metrics(keys, p, 25.0, 0.0, RANK)
    np.testing.assert_array_equal(np.asarray(a["mean_psnr"]), np.asarray(b["mean_psnr"]))
    np.testing.assert_array_equal(np.asarray(ca), np.asarray(cb))
    assert np.asarray(ca).shape == (6, 16) and np.asarray(ca).max() < 12
    with pytest.raises(ValueError, match="v_c must be finite and > 0"):
        dwell_switch_metrics(keys, p, -1.0, 0.0, RANK)
    with pytest.raises(ValueError, match="k_star must be in"):
        dwell_switch_metrics(keys, p, 25.0, 0.0, RANK, k_star=[0.0])


def test_switching_is_a_pure_function_under_jit_and_vmap(p, keys):
    """The same episodes through an outer jit (traced B) as through the plain call."""
    sw = switching(16, 1, 12)
    table = knob_table(25.0, 0.0)
    m, _, _ = rollout_switching(sw, keys, p, table, jnp.asarray(RANK))
    outer = jax.jit(lambda b: rollout_switching(sw, keys, p.replace(B=b), table, jnp.asarray(RANK))[0]["mean_psnr"])
    np.testing.assert_allclose(np.asarray(outer(jnp.float32(25e3))), np.asarray(m["mean_psnr"]), rtol=1e-6)
    assert isinstance(sw, Switching)
