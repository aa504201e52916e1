"""The agent object: one-file save/load, act, evaluate (semuav_jax/agents/agent.py)."""

import jax
import numpy as np
import pytest

from semuav_jax.agents.agent import Agent, evaluate
from semuav_jax.env import reset_state, transition_u
from semuav_jax.keys import episode_keys
from semuav_jax.metrics import episode_metrics
from semuav_jax.rollout import delay_draws


@pytest.fixture(scope="module")
def agent():
    return Agent.shipped(seed=1)


def test_save_load_round_trip(agent, tmp_path):
    path = agent.save(tmp_path / "a.msgpack")
    back = Agent.load(path)
    assert back.run == agent.run and back.config == agent.config
    for a, b in zip(jax.tree.leaves(agent.weights), jax.tree.leaves(back.weights)):
        np.testing.assert_array_equal(a, b)
    state = reset_state(jax.random.key(3), agent.params)
    assert int(back.act(state)[0]) == int(agent.act(state)[0])


def test_load_refuses_other_files(tmp_path):
    (tmp_path / "x").write_bytes(b"not an agent")
    with pytest.raises(ValueError, match="not a semuav-jax agent file"):
        Agent.load(tmp_path / "x")
    with pytest.raises(ValueError, match="seeds 0..2"):
        Agent.shipped(seed=3)


def test_evaluate_is_a_loop_of_act(agent):
    """evaluate()'s mean PSNR equals a plain Python loop of act + transition over the same episodes
    (the policy state, an option agent's running option, handed from one act to the next; the
    episode starting from the agent's numbering of the devices)."""
    params = agent.params.replace(B=20e3)
    keys = episode_keys(11, 3)
    act = jax.jit(lambda s, ps: agent.act(s, params, ps)[1:])
    first = jax.jit(lambda s: agent.act(s, params)[1:])
    step = jax.jit(lambda u, s, a: transition_u(u, s, a, params)[0])
    psnr, arrived = [], []
    for key in keys:
        k_reset, k_steps = jax.random.split(key)
        state, ps = agent.numbered(reset_state(k_reset, params), params), None
        for u in delay_draws(k_steps, params):
            accel, ps = first(state) if ps is None else act(state, ps)
            state = step(u, state, accel)
        m = episode_metrics(state, params)
        psnr.append(float(m["mean_psnr"]))
        arrived.append(bool(m["arrived"]))
    r = evaluate(agent, params, episodes=3, seed=11)
    assert r["mean_psnr"][0] == pytest.approx(np.mean(psnr), abs=1e-4)
    assert r["arrived"][0] == np.mean(arrived)
    lo, hi = r["arrived"][1]
    assert 0.0 <= lo <= r["arrived"][0] <= hi <= 1.0
