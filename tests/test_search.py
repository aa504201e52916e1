"""The agent with search at the BS (semuav_jax/agents/search.py, docs/model.md eq. 7.15): with no
alternative it is the greedy agent; a forced candidate is the agent's action for ``every`` slots."""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.evaluate import evaluate_agent
from semuav_jax.agents.network import q_network
from semuav_jax.agents.policy import input_size
from semuav_jax.agents.search import search_metrics, search_switching
from semuav_jax.lookahead import rollout_switching
from semuav_jax.params import make_params

ROOT = Path(__file__).resolve().parents[1]

CFG = DDQNConfig(hidden=(16,), actions="waypoint", shield_margin=2.0)


def _agent(curves):
    params = make_params(curves, B=25e3, K=60)
    network = q_network(params, CFG)
    net = network.init(jax.random.key(1), jnp.zeros((input_size(params, CFG),)))
    return params, network, net


def test_with_only_the_agent_as_candidate_it_is_the_greedy_agent(curves):
    params, network, net = _agent(curves)
    keys = jax.random.split(jax.random.PRNGKey(4), 4)
    m, chosen, _ = rollout_switching(search_switching(network, CFG, 8, 1, 0), keys, params, net)
    ref = evaluate_agent(network, net, CFG, keys, params)
    for k in ("mean_psnr", "arrived", "mission_time", "shield_share"):
        np.testing.assert_allclose(np.asarray(m[k]), ref[k], rtol=1e-6, err_msg=k)
    assert np.all(np.asarray(chosen) == 0)


def test_search_candidates_and_their_choices(curves):
    params, network, net = _agent(curves)
    sw = search_switching(network, CFG, 8, 1, 16)
    own, third = sw.candidate(net, None, jnp.int32(0)), sw.candidate(net, None, jnp.int32(3))
    assert (int(own.left), int(third.action), int(third.left)) == (0, 2, 8)
    keys = jax.random.split(jax.random.PRNGKey(5), 3)
    m, chosen, _ = search_metrics(net, CFG, keys, params, every=8)
    assert np.asarray(chosen).shape == (3, 8) and 0 <= np.asarray(chosen).min() and np.asarray(chosen).max() <= 16
    assert np.all(np.isfinite(np.asarray(m["mean_psnr"])))


def test_the_search_comparison_needs_the_runs_dwell_tuning(tmp_path):
    """compare_search reads the dwell knobs that the run's eval.json chose on validation layouts:
    without them (or with too few layouts) it stops with one line before any simulation."""
    import json
    import shutil

    import pytest

    from semuav_jax.experiments.search import compare_search

    folder = tmp_path / "agent"
    shutil.copytree(ROOT / "semuav_jax" / "data" / "agent", folder)
    r = json.loads((folder / "eval.json").read_text())
    r["tuning"].pop("dwell-switch", None)
    (folder / "eval.json").write_text(json.dumps(r))
    with pytest.raises(ValueError, match="has no dwell tuning"):
        compare_search(folder, episodes=4)
    with pytest.raises(ValueError, match="episodes must be >= 2"):
        compare_search(folder, episodes=1)


def test_the_search_command_says_what_to_run_first(tmp_path, capsys):
    """``semuav-search`` on a run folder without the dwell tuning: exit 2 and one line naming semuav-compare."""
    import json
    import shutil

    import pytest

    from semuav_jax.cli.search import main

    folder = tmp_path / "agent"
    shutil.copytree(ROOT / "semuav_jax" / "data" / "agent", folder)
    r = json.loads((folder / "eval.json").read_text())
    r.pop("tuning")
    (folder / "eval.json").write_text(json.dumps(r))
    with pytest.raises(SystemExit) as e:
        main([str(folder), "--episodes", "4"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "has no dwell tuning" in err and "run semuav-compare on it first" in err, err
    with pytest.raises(SystemExit) as e:  # --tuning names the file it read
        main([str(folder), "--episodes", "4", "--tuning", str(tmp_path / "none.json")])
    err = capsys.readouterr().err
    assert e.value.code == 2 and f"{tmp_path / 'none.json'} has no dwell tuning" in err, err
    with pytest.raises(SystemExit) as e:  # a bad search knob: one line before any reference is flown
        main([str(ROOT / "semuav_jax" / "data" / "agent"), "--episodes", "4", "--every", "0"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "every must be an integer >= 1, got 0" in err, err


def test_option_search_goes_on_with_the_agent_or_starts_an_option(curves):
    """Options (eq. 6.4): with only candidate 0 (go on) and a decision every slot the search is the
    greedy option agent (its tour re-planned every slot, as the agent plans it); the candidate c > 0
    forces option c - 1 at the next slot and keeps the running option otherwise."""
    from semuav_jax.actions import OPTION_HOME
    from semuav_jax.agents.options import idle
    from semuav_jax.agents.search import option_switching
    from semuav_jax.env import reset_state

    cfg = DDQNConfig(hidden=(16,), actions="option", shield_margin=2.0)
    params = make_params(curves, B=25e3, K=60)
    network = q_network(params, cfg)
    net = network.init(jax.random.key(1), jnp.zeros((input_size(params, cfg),)))
    keys = jax.random.split(jax.random.PRNGKey(4), 4)
    only = option_switching(network, cfg, 1, 1, 0)._replace(count=1)
    m, chosen, _ = rollout_switching(only, keys, params, net)
    ref = evaluate_agent(network, net, cfg, keys, params)
    for k in ("mean_psnr", "arrived", "mission_time", "shield_share"):
        np.testing.assert_allclose(np.asarray(m[k]), ref[k], rtol=1e-6, err_msg=k)
    sw = option_switching(network, cfg, 8, 1, 2)  # continue, 2 x 6 options, home
    assert sw.count == 14
    state, tour = reset_state(jax.random.key(7), params), jnp.arange(params.N, dtype=jnp.int32)
    now = ((net, jnp.int32(-1), tour), idle().replace(code=jnp.int32(4), active=jnp.bool_(True)))
    keep, third, home = (sw.candidate(net, None, jnp.int32(c), now, state, params)[1] for c in (0, 3, 13))
    assert (int(keep.forced), int(keep.code)) == (-1, 4)
    assert (int(third.forced), int(third.code)) == (2, 4)
    assert int(home.forced) == OPTION_HOME
    m, chosen, _ = search_metrics(net, cfg, keys, params, every=8)  # 4 targets x 6 options, home, 12 rules
    assert np.asarray(chosen).shape == (4, 8) and np.asarray(chosen).max() <= 37
    assert np.all(np.isfinite(np.asarray(m["mean_psnr"])))


def test_the_search_bar_counts_one_step_per_seed_and_bandwidth(tmp_path):
    """semuav-search's progress bar: one step per (bandwidth, seed) line the search logs, 4 x 3 for
    the shipped run; None (a bar without a total) where the folder has no readable config."""
    from semuav_jax.cli.search import cells

    assert cells(str(ROOT / "semuav_jax" / "data" / "agent")) == 4 * 3
    assert cells(str(tmp_path)) is None
    (tmp_path / "config.json").write_text("{not json")
    assert cells(str(tmp_path)) is None


@pytest.mark.slow
def test_the_search_table_names_the_layouts_it_used():
    """semuav-search's table and JSON state the layout stream of its keys (validation here) and
    one paired row per seed: the shipped agent on 2 validation layouts at 25 kHz."""
    from semuav_jax.experiments.search import compare_search, markdown
    from semuav_jax.keys import VALIDATION_SEED

    r = compare_search(ROOT / "semuav_jax" / "data" / "agent", episodes=2, bandwidths=(25e3,), validation=True,
                       log=lambda _: None)  # fmt: skip
    assert r["layout_seed"] == VALIDATION_SEED and r["layouts"] == "validation"
    assert f"First 2 validation layouts (seed {VALIDATION_SEED})" in markdown(r)
    knobs = "a decision every 10 slots, 4 target devices, the agent's 4 best options by Q, 15 rules (constant options"
    assert r["rules"] == 15 and knobs in markdown(r)  # the defaults: SEARCH_EVERY, SEARCH_TARGETS, SEARCH_TOP
    (row,) = r["rows"]
    assert len(row["seeds"]) == r["seeds"] == 3
    for s in row["seeds"]:
        np.testing.assert_allclose(s["minus agent"][0], s["mean_psnr"][0] - s["agent"][0], atol=1e-4)
        # bound - agent = (bound - search) + (search - agent), layout by layout, so in the mean too
        np.testing.assert_allclose(s["agent bound gap"][0], s["bound gap"][0] + s["minus agent"][0], atol=1e-4)
    assert "| bound − search | bound − agent |" in markdown(r)
    light = compare_search(ROOT / "semuav_jax" / "data" / "agent", episodes=2, bandwidths=(25e3,), validation=True,
                           references=False, log=lambda _: None)  # fmt: skip
    assert light["versus"] == ["agent"] and light["rows"][0]["references"] == {}
    for s, full in zip(light["rows"][0]["seeds"], row["seeds"]):  # the same flights, fewer columns
        assert s["mean_psnr"] == full["mean_psnr"] and "bound gap" not in s and "minus tsp-dwell" not in s
    assert "search − agent | s |" in markdown(light) and "tsp-dwell" not in markdown(light)


def test_option_search_with_top_simulates_the_agents_best_options(curves):
    """``top``: a decision simulates going on (c = 0) and the options with the highest Q, candidate
    c = option c - 1, home the last; with every option in the shortlist the search is the full one."""
    from semuav_jax.actions import OPTION_HOME
    from semuav_jax.agents.policy import agent_input
    from semuav_jax.agents.search import option_switching
    from semuav_jax.env import reset_state

    cfg = DDQNConfig(hidden=(16,), actions="option", shield_margin=2.0)
    params = make_params(curves, B=25e3, K=60)
    network = q_network(params, cfg)
    net = network.init(jax.random.key(1), jnp.zeros((input_size(params, cfg),)))
    state = reset_state(jax.random.key(7), params)
    q = np.asarray(network.apply(net, agent_input(state, params, cfg)))
    sw = option_switching(network, cfg, 8, 1, 2, 3)  # continue, 2 x 6 options, home: 14 candidates
    q2 = np.concatenate([q[:12], q[OPTION_HOME:]])  # candidate c >= 1 has Q index c - 1
    ids = np.asarray(sw.shortlist(net, None, state, None, params))
    assert ids[0] == 0 and sorted(ids[1:] - 1) == sorted(np.argsort(-q2)[:3])
    keys = jax.random.split(jax.random.PRNGKey(4), 3)
    full, every_one = (search_metrics(net, cfg, keys, params, 8, 1, 2, top)[0] for top in (None, 13))
    np.testing.assert_allclose(np.asarray(every_one["mean_psnr"]), np.asarray(full["mean_psnr"]), rtol=1e-6)
    with pytest.raises(ValueError, match=r"top must be in \[1, 13\]"):
        option_switching(network, cfg, 8, 1, 2, 14)


def test_option_search_switches_to_constant_options_and_keeps_them(curves):
    """``rules``: candidate targets L + 2 + i starts the constant option rules[i] now, along the
    tour planned at the decision (eq. 6.5), and chooses it at every later decision (going on, c = 0,
    keeps rule and tour); an agent's candidate (c >= 1), and the agent going on, take the tour
    planned at the decision. A rule on the nearest device (no tour) flies as the constant option
    does (eq. 6.4), and the light policy simulates every rule to the values the agent's own policy
    gives."""
    from semuav_jax.agents.options import idle, option_observe, planned_tour
    from semuav_jax.agents.policy import choice_policy
    from semuav_jax.agents.search import option_switching
    from semuav_jax.env import reset_state
    from semuav_jax.lookahead import check_switching, choose
    from semuav_jax.rollout import rollout

    cfg = DDQNConfig(hidden=(16,), actions="option", shield_margin=2.0)
    params = make_params(curves, B=25e3, K=60)
    network = q_network(params, cfg)
    net = network.init(jax.random.key(1), jnp.zeros((input_size(params, cfg),)))
    sw = option_switching(network, cfg, 8, 1, 2, None, (3, 15))  # go on, 2 x 6 options, home, 2 rules
    assert sw.count == 16
    state = reset_state(jax.random.key(7), params)
    planned = np.asarray(
        planned_tour(option_observe(lambda s, p: jnp.zeros(0), cfg.option_margin)(state, params), params)
    )
    tour = jnp.asarray(planned[::-1].copy())  # a tour planned earlier, not the one planned now
    assert sorted(planned) == list(range(params.N)) and not np.array_equal(planned, np.asarray(tour))
    now = ((net, jnp.int32(-1), tour), idle().replace(code=jnp.int32(4), active=jnp.bool_(True)))
    (_, rule, t), opt = sw.candidate(net, None, jnp.int32(15), now, state, params)
    assert (int(rule), int(opt.forced)) == (15, 15) and np.array_equal(np.asarray(t), planned)
    ruling = ((net, rule, tour), opt.replace(forced=jnp.int32(-1)))
    (_, rule, t), opt = sw.candidate(net, None, jnp.int32(0), ruling, state, params)
    assert (int(rule), int(opt.forced)) == (15, -1) and np.array_equal(np.asarray(t), np.asarray(tour))
    for c, forced in ((2, 1), (0, -1)):  # the agent: an option started now, or going on
        ps = ((net, jnp.int32(-1 if c == 0 else 15), tour), ruling[1])
        (_, rule, t), opt = sw.candidate(net, None, jnp.int32(c), ps, state, params)
        assert (int(rule), int(opt.forced)) == (-1, forced) and np.array_equal(np.asarray(t), planned)
    keys = jax.random.split(jax.random.PRNGKey(4), 4)
    m = rollout(sw.policy, keys, params, ((net, jnp.int32(15), tour), idle()), state_axes=None)[0]
    ref = rollout(choice_policy(lambda o, x, p: o, cfg), keys, params, (jnp.int32(15), idle()), state_axes=None)[0]
    for k in ("mean_psnr", "arrived", "mission_time"):
        np.testing.assert_array_equal(np.asarray(m[k]), np.asarray(ref[k]), err_msg=k)
    for s in (sw, option_switching(network, cfg, 8, 1, 2, 3, (3, 15))):
        now = ((net, jnp.int32(-1), tour), idle())
        light = choose(check_switching(s), state, net, None, jax.random.key(3), params, now)[1]
        heavy = choose(check_switching(s._replace(light=None)), state, net, None, jax.random.key(3), params, now)[1]
        assert light.shape == ((16,) if s.shortlist is None else (6,))
        np.testing.assert_array_equal(np.asarray(light), np.asarray(heavy))
    with pytest.raises(ValueError, match=r"rules must be options in \[0, 24\), got \[24\]"):
        option_switching(network, cfg, 8, 1, 2, None, (24,))
    with pytest.raises(ValueError, match=r"light.count must be an integer in \[1, 16\), got 16"):
        check_switching(sw._replace(light=sw.light._replace(count=16)))


def test_curve_rules_choose_k_on_the_devices_curve(curves):
    """A curve rule (``curves``) serves the first device along the tour until the k of OPTION_K that
    maximizes C[i_n, k] - phi_n - lambda (k - m_n) beta / R(0), computed here by hand: lambda 0 takes
    the k of the largest gain, a huge lambda the smallest k. Its candidate forces no option but ends
    the running one, so the rule decides at the next slot; the light policy simulates it to the
    values the agent's own policy gives; lambdas must be floats >= 0."""
    from semuav_jax import channel
    from semuav_jax.actions import OPTION_HOME, OPTION_K
    from semuav_jax.agents.features import curve_gains
    from semuav_jax.agents.options import idle, option_observe
    from semuav_jax.agents.search import option_switching, rule_choice
    from semuav_jax.env import reset_state
    from semuav_jax.lookahead import check_switching, choose

    cfg = DDQNConfig(hidden=(16,), actions="option", shield_margin=2.0)
    params = make_params(curves, B=25e3)  # the whole mission: some devices fit
    state = reset_state(jax.random.key(7), params)
    observe = option_observe(curve_gains, cfg.option_margin)
    n0 = int(np.argmax(np.asarray(observe(state.replace(m=state.m * 0.0), params).fits)))  # a device that fits
    state = state.replace(m=state.m.at[:].set(0.0).at[n0].set(10.0), phi=state.phi.at[n0].set(7.0))
    obs = observe(state, params)
    tour = jnp.asarray([n0] + [n for n in range(int(params.N)) if n != n0], jnp.int32)
    C, img = np.asarray(params.C), int(state.dev_img[n0])
    k = np.asarray(OPTION_K)
    gain = np.maximum(C[img, k.astype(int)] - 7.0, 0.0)
    stay = (k - 10.0) * float(params.beta) / float(channel.rest_rate(params))
    assert bool(obs.fits[n0])  # device n0, first along the tour, is every option's device
    assert np.argmax(gain) > 0  # lambda 0 and a huge lambda choose different k
    for lam, i in zip((0.0, 0.5, 1e4), range(3)):
        rule = jnp.int32(OPTION_HOME + 1 + i)
        want = np.argmax(gain - lam * stay)
        got = int(rule_choice(rule, obs.x, obs, tour, params, (0.0, 0.5, 1e4)))
        assert got == want, (lam, got, want)
    assert int(rule_choice(jnp.int32(7), obs.x, obs, tour, params, (0.5,))) == 7
    network = q_network(params, cfg)
    net = network.init(jax.random.key(1), jnp.zeros((input_size(params, cfg),)))
    sw = option_switching(network, cfg, 8, 1, 2, None, (3,), (0.5,))  # go on, 12 options, home, 2 rules
    assert sw.count == 16 and sw.light.count == 2
    now = ((net, jnp.int32(-1), tour), idle().replace(code=jnp.int32(4), active=jnp.bool_(True)))
    (_, rule, _), opt = sw.candidate(net, None, jnp.int32(15), now, state, params)
    assert (int(rule), int(opt.forced), bool(opt.active)) == (OPTION_HOME + 1, -1, False)
    fresh = reset_state(jax.random.key(7), params)
    now = ((net, jnp.int32(-1), tour), idle())
    light = choose(check_switching(sw), fresh, net, None, jax.random.key(3), params, now)[1]
    heavy = choose(check_switching(sw._replace(light=None)), fresh, net, None, jax.random.key(3), params, now)[1]
    np.testing.assert_array_equal(np.asarray(light), np.asarray(heavy))
    with pytest.raises(ValueError, match=r"curves must be lambdas >= 0"):
        option_switching(network, cfg, 8, 1, 2, None, (3,), (-1.0,))
