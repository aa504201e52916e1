"""semuav_jax/agents/gym_shield.py: the BS's shield around the Gymnasium adapters."""

import numpy as np
import pytest

from semuav_jax.actions import HOME
from semuav_jax.agents.gym_shield import ShieldWrapper, VectorShieldWrapper
from semuav_jax.gym_adapter import SemUAVGymEnv
from semuav_jax.gym_vector import SemUAVVectorEnv

K = 12  # 6 s: at q0, 1000 m from q_fin, too late from the first slot: the shield always flies home
E = 4


def test_single_env_sends_the_home_action_when_late(curves):
    """At rest at q0 the home action is table action 7 (+x, test_shield.py); the wrapped env steps as
    the bare env stepped with 7."""
    shielded, bare = ShieldWrapper(SemUAVGymEnv(curves=curves, K=K)), SemUAVGymEnv(curves=curves, K=K)
    shielded.reset(seed=3)
    bare.reset(seed=3)
    obs, rew, *_, info = shielded.step(0)
    obs_b, rew_b, *_ = bare.step(7)
    np.testing.assert_array_equal(obs, obs_b)
    assert rew == rew_b and info["shielded"] is True
    with pytest.raises(ValueError, match="action must be an integer"):
        shielded.step(9)


def test_not_late_passes_actions_through(curves):
    env = ShieldWrapper(SemUAVGymEnv(curves=curves), margin=2.0)  # K = 250: 125 s, home needs ~52 s
    env.reset(seed=0)
    for a in range(9):
        assert env.step(a)[-1]["shielded"] is False


@pytest.mark.parametrize("actions", ["table", "waypoint"])
def test_vector_wrapper_equals_single_wrappers(curves, actions):
    vec = VectorShieldWrapper(SemUAVVectorEnv(num_envs=E, actions=actions, curves=curves, K=K))
    singles = [ShieldWrapper(SemUAVGymEnv(actions=actions, curves=curves, K=K)) for _ in range(E)]
    vec.reset(seed=8)
    for i, s in enumerate(singles):
        s.reset(seed=8 + i)
    rng = np.random.default_rng(0)
    for _ in range(K):
        a = rng.integers(0, vec.single_action_space.n, E)
        obs, rew, term, _, info = vec.step(a)
        for i, s in enumerate(singles):
            o, r, t, _, inf = s.step(int(a[i]))
            np.testing.assert_allclose(obs[i], o, rtol=1e-5, atol=1e-5)
            assert r == pytest.approx(rew[i], rel=1e-5, abs=1e-5)
            assert t == term[i] and inf["shielded"] == info["shielded"][i]
    if actions == "waypoint":  # late from the start: every action is HOME
        assert info["shielded"].tolist() == (a != HOME).tolist()


@pytest.mark.parametrize("margin", [-1.0, float("inf"), float("nan"), "2"])
def test_bad_margin(curves, margin):
    with pytest.raises(ValueError, match="margin must be a finite number of seconds >= 0, got") as err:
        ShieldWrapper(SemUAVGymEnv(curves=curves, K=K), margin=margin)
    assert "\n" not in str(err.value)
