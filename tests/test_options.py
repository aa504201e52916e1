"""Options (docs/model.md eq. 6.4): codes and commands by hand, the option's life in a flight, the
semi-MDP transitions of agents/smdp.py by hand, the masked replay write, and option training."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import short_option_training

from semuav_jax.actions import (
    DWELL_SPEED,
    HOME_CODE,
    NUM_OPTIONS,
    OPTION_HOME,
    OPTION_K,
    TOUR_TARGETS,
    device_order,
    option_accel,
    option_code,
    option_codes,
)
from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.options import OptionObs, idle, running, step_option
from semuav_jax.agents.policy import greedy_policy
from semuav_jax.agents.replay import Transition, replay_add_where, replay_init
from semuav_jax.agents.smdp import option_transitions, pending_init
from semuav_jax.control import STOP_BRAKE, home_command, speed_command
from semuav_jax.env import reset_state

L = len(OPTION_K)


@pytest.fixture
def state(params):
    s = reset_state(jax.random.key(0), params)
    pos = jnp.array([[100.0, 300.0], [130.0, 340.0], [50.0, 300.0], [400.0, 100.0], [900.0, 500.0],
                     [60.0, 310.0], [700.0, 300.0], [20.0, 250.0], [500.0, 550.0], [300.0, 300.0]])  # fmt: skip
    return s.replace(dev_pos=pos, q=jnp.array([40.0, 300.0]), v=jnp.zeros(2), m=jnp.zeros(10).at[2].set(256.0))


def test_option_codes_by_hand(state, params):
    """Option j L + i serves, until k = OPTION_K[i], the j-th candidate along the tour for j <
    TOUR_TARGETS, else the (j - TOUR_TARGETS)-th nearest (the last candidate when fewer); the last
    option is home. From (40, 300) the devices nearest first are 5 (22.4 m), 7 (53.9 m), 0 (60 m),
    1, ...; device 2 is finished; device 7 holds 20 symbols; the tour here is given by hand."""
    s = state.replace(m=state.m.at[7].set(20.0))
    order, m, fits = device_order(s, params), s.m, jnp.ones(10, bool)
    tour = jnp.array([9, 7, 3, 6, 4, 8, 1, 0, 5, 2])
    assert list(np.asarray(order[:4])) == [5, 7, 0, 1]
    near = TOUR_TARGETS * L
    want = {0: (9, 16.0), 1: (9, 24.0), L: (3, 16.0), L + 1: (7, 24.0), near: (5, 16.0), near + L: (0, 16.0),
            near + L + 1: (7, 24.0), near + 5: (5, 96.0)}  # fmt: skip
    for choice, (n, k) in want.items():
        code, kk = option_code(jnp.int32(choice), m, fits, order, tour, params)
        assert (int(code), float(kk)) == (n, k), choice
    code, kk = option_code(jnp.int32(OPTION_HOME), m, fits, order, tour, params)
    assert int(code) == HOME_CODE and float(kk) == np.inf
    codes, ks = option_codes(NUM_OPTIONS, m, fits, order, tour, params)  # the vmap is the loop
    for choice, (n, k) in want.items():
        assert (int(codes[choice]), float(ks[choice])) == (n, k), choice
    assert int(codes[OPTION_HOME]) == HOME_CODE and codes.shape == ks.shape == (NUM_OPTIONS,)
    few = jnp.full(10, 256.0).at[4].set(0.0).at[6].set(0.0)  # devices 4 and 6 short
    assert int(option_code(jnp.int32(L), few, fits, order, tour, params)[0]) == 4  # 6 first on the tour, then 4
    assert (
        int(option_code(jnp.int32(near + L), few, fits, device_order(s.replace(m=few), params), tour, params)[0]) == 4
    )
    assert int(option_code(jnp.int32(0), jnp.full(10, 256.0), fits, order, tour, params)[0]) == HOME_CODE
    # device 5 no longer fits: the nearest candidate short of 16 is 0 (7 holds 20 >= 16)
    assert int(option_code(jnp.int32(near), m, fits.at[5].set(False), order, tour, params)[0]) == 0


@pytest.mark.parametrize("margin", [-2.0, -4.0, 1.0])
def test_options_serve_only_devices_that_fit(state, params, margin):
    """Eq. 7.9: a device fits while the stop there and the flight home (eqs. 7.4-7.5 at DWELL_SPEED)
    take at most the time left less the margin; every device fits at t = 0."""
    from semuav_jax.actions import option_fits
    from semuav_jax.control import time_via

    assert bool(jnp.all(option_fits(state, params, margin)))
    need = np.array([float(time_via(state.q, state.v, p, DWELL_SPEED, params, stop=True)) for p in state.dev_pos])
    slots = int(np.ceil((np.median(need) + margin) / params.tau))  # about half of them fit
    late = state.replace(t=jnp.int32(params.K - slots))
    fits = np.asarray(option_fits(late, params, margin))
    np.testing.assert_array_equal(fits, need + margin <= slots * params.tau)
    assert 0 < int(np.sum(fits)) < 10
    observe = greedy_policy(None, DDQNConfig(actions="option", option_margin=margin)).observe
    np.testing.assert_array_equal(np.asarray(observe(late, params).fits), fits)


def test_constant_options_are_the_dwell_rules(params):
    """The first nearest option of one k, chosen at every decision, visits the nearest device short
    of k and stays until k, as greedy-dwell with k* = k; option i (the first along the re-planned
    tour) flies as TSP-dwell does on the shortest path: the same PSNR within the missing time test
    (the BS's shield flies home instead) and the tour's few metres."""
    from baselines.dwell import dwell_metrics, greedy_dwell, tsp_dwell
    from baselines.evaluate import tsp_ranks
    from semuav_jax.agents.policy import choice_policy, initial_state
    from semuav_jax.rollout import rollout

    cfg = DDQNConfig(actions="option", shield_margin=2.0)
    keys = jax.random.split(jax.random.key(5), 32)
    i = OPTION_K.index(48.0)
    rank = np.asarray(tsp_ranks(keys, params, workers=1))
    for choice, rule, ranks in (
        (TOUR_TARGETS * L + i, greedy_dwell, np.zeros((32, 10), np.int32)),
        (i, tsp_dwell, rank),
    ):
        pol = choice_policy(lambda inner, x, p, c=choice: jnp.int32(c), cfg)
        m = rollout(pol, keys, params, initial_state(jnp.zeros(()), cfg), state_axes=None)[0]
        g = dwell_metrics(rule, keys, params, DWELL_SPEED, 48.0, -2.0, ranks)
        assert bool(np.all(m["arrived"]))
        assert abs(float(m["mean_psnr"].mean()) - float(g["mean_psnr"].mean())) < 1.0, rule
        assert float(np.mean(m["symbol_fraction"])) > 0.9 * float(np.mean(g["symbol_fraction"]))


def test_option_commands_by_hand(state, params):
    """Code n: cruise at DWELL_SPEED to device n braking with STOP_BRAKE (eq. 7.3), whatever the
    order; HOME_CODE: the home command at v_max."""
    d7 = float(np.hypot(20.0, 50.0))
    speed = min(DWELL_SPEED, np.sqrt(2 * STOP_BRAKE * 5.0 * d7))
    want = speed_command(state.q, state.v, state.dev_pos[7], speed, params)
    np.testing.assert_allclose(option_accel(jnp.int32(7), state, params), want, rtol=1e-5)
    home = home_command(state.q, state.v, params.v_max, params)
    np.testing.assert_allclose(option_accel(jnp.int32(HOME_CODE), state, params), home)


def test_an_option_runs_until_its_device_holds_k_symbols(state, params):
    """A decision fixes (device, k); the option goes on while m_n < k and ends at k; a forced choice
    is a decision at once; the home option goes on while no more devices are live."""
    obs = lambda s: OptionObs(jnp.zeros(3), s.m, jnp.ones(10, bool), device_order(s, params), s.q, s.dev_pos)
    near = TOUR_TARGETS * L
    opt = step_option(idle(), jnp.int32(near + L + 1), obs(state), params)  # device 7 until 24 symbols
    assert bool(opt.decided) and (int(opt.code), float(opt.k), int(opt.choice)) == (7, 24.0, near + L + 1)
    moved = state.replace(q=state.dev_pos[7], m=state.m.at[7].set(23.0))  # the order changed: 7 is first
    nxt = step_option(opt, jnp.int32(near), obs(moved), params)
    assert not bool(nxt.decided) and int(nxt.code) == 7 and bool(running(opt, obs(moved), params))
    done = moved.replace(m=moved.m.at[7].set(24.0))
    assert not bool(running(opt, obs(done), params))
    new = step_option(opt, jnp.int32(near), obs(done), params)
    assert bool(new.decided) and int(new.code) == 5  # from device 7, 5 (72 m) is the nearest short of 16
    forced = step_option(opt.replace(forced=jnp.int32(OPTION_HOME)), jnp.int32(0), obs(moved), params)
    assert bool(forced.decided) and int(forced.code) == HOME_CODE and int(forced.forced) == -1
    home = step_option(idle(), jnp.int32(OPTION_HOME), obs(state), params)
    assert bool(running(home, obs(state.replace(m=jnp.full(10, 256.0))), params))


def test_an_option_ends_when_its_device_stops_fitting(state, params):
    """Eq. 7.9: short of k, the option still ends once its device no longer fits (the dwell rules'
    test); the next decision chooses among the devices that fit; the home option goes on while
    devices stop fitting."""
    obs = lambda s, fits: OptionObs(jnp.zeros(3), s.m, fits, device_order(s, params), s.q, s.dev_pos)
    near = TOUR_TARGETS * L
    all_fit = jnp.ones(10, bool)
    opt = step_option(idle(), jnp.int32(near + L + 1), obs(state, all_fit), params)  # device 7 until 24
    at7 = state.replace(q=state.dev_pos[7], m=state.m.at[7].set(10.0))
    assert bool(running(opt, obs(at7, all_fit), params))
    gone = all_fit.at[7].set(False)
    assert not bool(running(opt, obs(at7, gone), params))
    nxt = step_option(opt, jnp.int32(near), obs(at7, gone), params)
    assert bool(nxt.decided) and int(nxt.code) == 5  # from device 7, 5 is the nearest that fits short of 16
    home = step_option(idle(), jnp.int32(OPTION_HOME), obs(state, all_fit), params)
    assert bool(running(home, obs(state, jnp.zeros(10, bool)), params))


def test_the_home_option_ends_when_a_device_becomes_live(state, params):
    """Home, chosen while devices 5 and 7 are live (short of OPTION_K[0] and fitting), goes on while
    those or fewer are; it ends when a third becomes live (flying off at speed, eqs. 7.4-7.5 can fit
    a device again, and a dwell rule turns to it), and the next decision serves it."""
    obs = lambda s, fits: OptionObs(jnp.zeros(3), s.m, fits, device_order(s, params), s.q, s.dev_pos)
    two = jnp.zeros(10, bool).at[5].set(True).at[7].set(True)
    home = step_option(idle(), jnp.int32(OPTION_HOME), obs(state, two), params)
    assert int(home.code) == HOME_CODE and int(home.live_at_decision) == 2
    assert bool(running(home, obs(state, two), params))
    assert bool(running(home, obs(state, two.at[7].set(False)), params))
    assert bool(running(home, obs(state, two.at[2].set(True)), params))  # device 2 holds 256: not live
    three = two.at[9].set(True)
    assert not bool(running(home, obs(state, three), params))
    nxt = step_option(home, jnp.int32(TOUR_TARGETS * L), obs(state.replace(q=state.dev_pos[9]), three), params)
    assert bool(nxt.decided) and int(nxt.code) == 9


def test_training_layouts_are_numbered_along_the_shortest_path(params, monkeypatch):
    """A policy that numbers devices trains on a pool of layouts numbered once: a restart is a pool
    layout, numbered along the shortest path; any other policy draws a new layout."""
    from semuav_jax.agents import layouts
    from semuav_jax.tour import shortest_path

    monkeypatch.setattr(layouts, "LAYOUT_POOL", 8)
    cfg = DDQNConfig(actions="option", tour="shortest")
    pool = layouts.layout_pool(greedy_policy(None, cfg), params, jax.random.key(1))
    assert pool[1].shape == (8, 10)
    s = layouts.restart_state(jax.random.key(2), params, pool)
    np.testing.assert_array_equal(shortest_path(s.q, s.dev_pos, params.q_fin), np.arange(10))
    drawn = [reset_state(jax.random.fold_in(pool[0], i), params).dev_pos for i in range(8)]
    assert any(np.array_equal(np.sort(np.asarray(d), 0), np.sort(np.asarray(s.dev_pos), 0)) for d in drawn)
    assert layouts.layout_pool(greedy_policy(None, DDQNConfig(actions="option")), params, jax.random.key(1)) is None
    with pytest.raises(ValueError, match="tour must be one of"):
        DDQNConfig(actions="option", tour="nearest")
    with pytest.raises(ValueError, match="needs actions='option'"):
        DDQNConfig(tour="shortest")


def test_semi_mdp_transitions_by_hand():
    """One env, decisions at slots 0 and 2, the episode ends after slot 3: the first option's
    transition is (x0, a0, r0 + g r1, x2, not done, g^2), the second (x2, a1, r2 + g r3, x4, done, g^2);
    nothing is stored at slot 0 (no decision before it)."""
    g = 0.9
    x = [jnp.full((1, 2), float(i)) for i in range(5)]
    r = [1.0, 2.0, 3.0, 4.0]
    empty = jax.tree.map(lambda a: a[:1], replay_init(1, 2).data)
    pend = pending_init(empty)
    out = []
    for t in range(4):
        opt = jax.tree.map(lambda a: a[None], idle()).replace(
            decided=jnp.array([t in (0, 2)]), choice=jnp.array([7 if t < 2 else 3], jnp.int32)
        )
        batch, valid, pend = option_transitions(pend, x[t], opt, jnp.array([r[t]]), x[t + 1], jnp.array([t == 3]), g)
        out += [jax.tree.map(lambda a, i=i: a[i], batch) for i in range(2) if bool(valid[i])]
    assert len(out) == 2
    first, second = out
    np.testing.assert_allclose(first.obs, x[0][0])
    np.testing.assert_allclose(first.next_obs, x[2][0])
    assert (int(first.action), float(first.done)) == (7, 0.0)
    np.testing.assert_allclose([first.reward, first.discount], [1.0 + g * 2.0, g**2], rtol=1e-6)
    np.testing.assert_allclose(second.obs, x[2][0])
    np.testing.assert_allclose(second.next_obs, x[4][0])
    assert (int(second.action), float(second.done)) == (3, 1.0)
    np.testing.assert_allclose([second.reward, second.discount], [3.0 + g * 4.0, g**2], rtol=1e-6)
    assert not bool(pend.started[0]) and not bool(pend.option.active[0])  # the next episode starts afresh


def test_the_masked_write_keeps_order_and_wraps():
    buf = replay_init(5, 1)
    tr = lambda v: Transition(v[:, None], v.astype(jnp.int32), v, v[:, None], v * 0, v * 0 + 1)
    buf = replay_add_where(buf, tr(jnp.arange(1.0, 5.0)), jnp.array([True, False, True, True]))
    assert (int(buf.pos), int(buf.size)) == (3, 3)
    assert list(np.asarray(buf.data.reward)) == [1.0, 3.0, 4.0, 0.0, 0.0]
    buf = replay_add_where(buf, tr(jnp.arange(5.0, 9.0)), jnp.array([True, True, True, False]))
    assert (int(buf.pos), int(buf.size)) == (1, 5)
    assert list(np.asarray(buf.data.reward)) == [7.0, 3.0, 4.0, 5.0, 6.0]


def test_option_training_stores_decisions_and_reproduces(curves):
    """A short option training: every stored discount is gamma^tau for a whole tau >= 1, the memory
    holds far fewer transitions than slots, and the same key gives the same weights."""
    cfg, ts, ts2, m = short_option_training(curves, "option")
    n = int(ts.replay.size)
    slots = (cfg.warmup_steps + 60) * cfg.num_envs
    assert 0 < n < slots / 2
    tau = np.log(np.asarray(ts.replay.data.discount[:n])) / np.log(cfg.gamma)
    np.testing.assert_allclose(tau, np.round(tau), atol=1e-3)
    assert tau.min() >= 1 - 1e-3
    assert set(np.unique(np.asarray(ts.replay.data.action[:n]))) <= set(range(NUM_OPTIONS))
    for a, b in zip(jax.tree.leaves(ts.params), jax.tree.leaves(ts2.params)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert np.all(np.isfinite(np.asarray(m["loss"])))


def test_option_inputs_by_hand(state, params):
    """option_features: the waypoint input, then per option (gain on its device's curve, stay, slack
    after it, has a device). From (40, 300) the nearest options all serve device 5 (no symbols yet):
    gain C[i_5, k] - phi_5 over the range of C, stay k beta / R(0), slack = time left - the flight
    via device 5 home - stay, both over T; with every device finished there is no option to describe."""
    from semuav_jax import channel
    from semuav_jax.agents.features import option_features, waypoint_features
    from semuav_jax.control import time_via

    x = np.asarray(jax.jit(lambda s, p: option_features(s, p, -2.0))(state, params))
    base = np.asarray(waypoint_features(state, params))
    np.testing.assert_allclose(x[: base.size], base, rtol=1e-5, atol=1e-6)  # jit rounds differently
    block = x[base.size :].reshape(OPTION_HOME, 4)
    C, T = np.asarray(params.C), params.K * params.tau
    span = C.max() - C.min()
    rate = float(channel.rest_rate(params)) / params.beta  # symbols per second at a hover
    via = float(time_via(state.q, state.v, state.dev_pos[5], DWELL_SPEED, params, stop=True))
    img, phi = int(state.dev_img[5]), float(state.phi[5])
    for i, k in enumerate(OPTION_K):
        gain, stay, slack, has = block[TOUR_TARGETS * L + i]
        assert has == 1.0
        np.testing.assert_allclose(gain, max(C[img, int(k)] - phi, 0.0) / span, rtol=1e-5)
        np.testing.assert_allclose(stay, k / rate / T, rtol=1e-5)
        np.testing.assert_allclose(slack, (params.K * params.tau - via - k / rate) / T, rtol=1e-5, atol=1e-6)
    done = state.replace(m=jnp.full(10, float(params.M)))
    assert not np.any(np.asarray(option_features(done, params, -2.0))[base.size :])


def test_option_inputs_need_options():
    with pytest.raises(ValueError, match="option_inputs"):
        DDQNConfig(actions="waypoint", option_inputs=True)
