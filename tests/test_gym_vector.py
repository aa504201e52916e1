"""docs/env_api.md, "Gymnasium: many envs at once": the jitted, vmapped VectorEnv against n single envs."""

import gymnasium
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import semuav_jax.gym_adapter  # noqa: F401  (registers SemUAV-v0)
from semuav_jax import gym_vector
from semuav_jax.gym_vector import SemUAVVectorEnv

K = 12  # short episodes: several autoresets within a few dozen steps
E = 4  # sub-envs (one shape: the tests share compiled programs)
N_SUBSET = gym_vector.SUBSET_MIN + 16  # enough sub-envs for resets of only the rows that need them


def vector_class(adapter: str):
    """The Gymnasium vector env, or SB3's VecEnv over it (skipped without stable-baselines3)."""
    if adapter == "sb3":
        pytest.importorskip("stable_baselines3")
        from semuav_jax.sb3 import SemUAVVecEnv

        return SemUAVVecEnv
    return SemUAVVectorEnv


def make_pair(curves, n, actions="table", mode=AutoresetMode.NEXT_STEP):
    """(ours, SyncVectorEnv over n SemUAVGymEnv). The destination 22 m from q0: some episodes arrive
    within a few slots, the others run to t = K, so sub-envs end and autoreset at different steps."""
    kw = {"num_envs": n, "actions": actions, "curves": curves, "K": K, "q_fin": [22.0, 300.0]}
    return (
        gymnasium.make_vec("SemUAV-v0", vectorization_mode="vector_entry_point", autoreset_mode=mode, **kw),
        gymnasium.make_vec("SemUAV-v0", vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}, **kw),
    )


def assert_infos_equal(a: dict, b: dict):
    assert sorted(a) == sorted(b)
    for k, x in a.items():
        if isinstance(x, dict):
            assert_infos_equal(x, b[k])
        elif x.dtype == object:  # final_obs: an observation where the mask is set, else None
            assert [o is None for o in x] == [o is None for o in b[k]]
            for o, o_ref in zip(x, b[k]):
                np.testing.assert_allclose(
                    o if o is not None else 0.0, o_ref if o_ref is not None else 0.0, rtol=1e-5, atol=1e-5
                )
        elif k.startswith("_") or x.dtype == bool:
            np.testing.assert_array_equal(x, b[k], err_msg=k)
        else:  # vmap rounds float32 differently from one env at a time: equal up to rounding
            np.testing.assert_allclose(x, b[k], rtol=1e-5, atol=1e-5, err_msg=k)


@pytest.mark.parametrize(
    "actions, mode, n",
    [
        ("table", AutoresetMode.NEXT_STEP, E),
        ("waypoint", AutoresetMode.NEXT_STEP, E),
        ("table", AutoresetMode.SAME_STEP, E),
        ("table", AutoresetMode.NEXT_STEP, N_SUBSET),
        ("table", AutoresetMode.SAME_STEP, N_SUBSET),
    ],
)
def test_vector_episodes_equal_single_envs(curves, actions, mode, n):
    """Same seeds, same actions: the vector env's episodes (through autoresets at different steps)
    are those of Gymnasium's SyncVectorEnv over n SemUAVGymEnv, infos and masks included. With
    n > SUBSET_MIN, steps where at most ``size`` sub-envs end reset only those rows, the others all."""
    vec, sync = make_pair(curves, n, actions, mode)
    assert isinstance(vec.unwrapped, SemUAVVectorEnv) and vec.metadata["autoreset_mode"] == mode
    assert vec.action_space == sync.action_space and vec.observation_space == sync.observation_space
    obs_v, _ = vec.reset(seed=11)
    obs_s, _ = sync.reset(seed=11)
    np.testing.assert_array_equal(obs_v, obs_s)
    rng = np.random.default_rng(0)
    ends, partial, counts = 0, 0, set()
    for _ in range(3 * K):
        a = rng.integers(0, vec.single_action_space.n, n)
        obs_v, r_v, term_v, trunc_v, info_v = vec.step(a)
        obs_s, r_s, term_s, trunc_s, info_s = sync.step(a)
        np.testing.assert_array_equal(term_v, term_s)
        assert not trunc_v.any() and not trunc_s.any()
        np.testing.assert_allclose(obs_v, obs_s, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(r_v, r_s, rtol=1e-5, atol=1e-5)
        assert_infos_equal(info_v, info_s)
        ends += int(term_v.sum())
        partial += int(0 < term_v.sum() < n)
        counts.add(int(term_v.sum()))
    assert ends >= 2 * n and partial >= 2  # autoresets, some of them of only part of the sub-envs
    size = vec.unwrapped._size
    if size < n:  # both paths of _replace_rows: a few rows gathered, and all rows
        assert any(0 < c <= size for c in counts) and any(c > size for c in counts), counts
    # a reset without seed continues each sub-env's key chain, as the single env does
    np.testing.assert_allclose(vec.reset()[0], sync.reset()[0], rtol=1e-5, atol=1e-5)


def test_next_step_autoreset(curves):
    """The step after `terminated` ignores its action and returns the new episode's first
    observation (t = 0), reward 0, terminated False, and masks the step infos out."""
    envs = [SemUAVVectorEnv(num_envs=E, curves=curves, K=K) for _ in range(2)]
    for env in envs:
        env.reset(seed=0)
        for _ in range(K):
            *_, term, _, _ = env.step(np.full(E, 4))
        assert term.all() and (np.asarray(env.state.t) == K).all()
    obs_a, r_a, term_a, _, info = envs[0].step(np.array([0, 8, 1, 7]))
    obs_b, r_b, term_b, *_ = envs[1].step(np.array([3, 2, 5, 5]))  # other actions: the same reset
    np.testing.assert_array_equal(obs_a, obs_b)
    assert (r_a == 0).all() and (r_b == 0).all() and not term_a.any() and not term_b.any()
    assert (np.asarray(envs[0].state.t) == 0).all() and (np.asarray(envs[0].state.m) == 0).all()
    assert info == {}  # every sub-env was reset: no step info, no metrics
    obs_a, r_a, *_ = envs[0].step(np.array([0, 8, 1, 7]))  # stepping again
    assert (np.asarray(envs[0].state.t) == 1).all()


def test_episode_metrics_on_the_final_step(curves):
    env = SemUAVVectorEnv(num_envs=E, curves=curves, K=K)
    env.reset(seed=2)
    for _ in range(K):
        _, _, term, _, info = env.step(np.zeros(E, np.int64))
    assert term.all() and info["_mean_psnr"].all()
    np.testing.assert_allclose(info["mean_psnr"], np.asarray(env.state.phi).mean(-1), rtol=1e-6)
    np.testing.assert_allclose(info["mission_time"], K * float(env.env_params.tau))


def test_one_compiled_step(curves):
    """Every step of all sub-envs is one call of one compiled program: no recompile across steps,
    autoresets or action values."""
    env = SemUAVVectorEnv(num_envs=E, curves=curves, K=K)
    env.reset(seed=0)
    env.step(np.zeros(E, np.int64))
    compiled = gym_vector._vector_step._cache_size()
    for a in range(2 * K):
        env.step(np.full(E, a % 9))
    assert gym_vector._vector_step._cache_size() == compiled


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"num_envs": 0}, "num_envs must be an integer >= 1, got 0"),
        ({"num_envs": -3}, "got -3"),
        ({"num_envs": 2.5}, "got 2.5"),
        ({"num_envs": True}, "got True"),
        ({"actions": "speed"}, "actions must be one of .*got 'speed'"),
        ({"render_mode": "human"}, "render_mode must be None or one of .*got 'human'"),
    ],
)
@pytest.mark.parametrize("adapter", ["gymnasium", "sb3"])
def test_bad_constructor_arguments(curves, adapter, kw, match):
    with pytest.raises(ValueError, match=match) as err:
        vector_class(adapter)(**({"num_envs": 2} | kw), curves=curves, K=K)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize(
    "actions, match",
    [
        (np.zeros(3, np.int32), r"shape \(4,\), got int32 \(3,\)"),
        (np.zeros((4, 1), np.int32), r"got int32 \(4, 1\)"),
        (np.zeros(4, np.float32), "got float32"),
        (np.zeros(4, bool), "got bool"),
        (np.array([0, 1, 9, 2]), r"in \[0, 8\], got values in \[0, 9\]"),
        (np.array([0, -1, 2, 2]), r"got values in \[-1, 2\]"),
    ],
)
@pytest.mark.parametrize("adapter", ["gymnasium", "sb3"])
def test_bad_actions(curves, adapter, actions, match):
    env = vector_class(adapter)(num_envs=E, curves=curves, K=K)
    env.reset()
    with pytest.raises(ValueError, match=match) as err:
        env.step(actions)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("seed", [2**32 - 1, -1, [1, 2], 1.5])
def test_bad_seeds(curves, seed):
    env = SemUAVVectorEnv(num_envs=3, curves=curves, K=K)
    with pytest.raises(ValueError, match="seed must be") as err:
        env.reset(seed=seed)
    assert "\n" not in str(err.value)


def test_sb3_vec_env_equals_dummy_vec_env(curves):
    """SB3's VecEnv API (same-step reset, terminal_observation): the episodes of DummyVecEnv over n
    SemUAVGymEnv for the same seed."""
    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.vec_env import DummyVecEnv

    from semuav_jax.gym_adapter import SemUAVGymEnv
    from semuav_jax.sb3 import SemUAVVecEnv

    kw = {"curves": curves, "K": K, "q_fin": [22.0, 300.0]}
    ours = SemUAVVecEnv(num_envs=E, **kw)
    ref = DummyVecEnv([lambda: SemUAVGymEnv(**kw)] * E)
    for env in (ours, ref):
        env.seed(5)
    np.testing.assert_array_equal(ours.reset(), ref.reset())
    rng = np.random.default_rng(1)
    ends = 0
    for _ in range(2 * K):
        a = rng.integers(0, 9, E)
        obs, rew, done, infos = ours.step(a)
        obs_r, rew_r, done_r, infos_r = ref.step(a)
        np.testing.assert_array_equal(done, done_r)
        np.testing.assert_allclose(obs, obs_r, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(rew, rew_r, rtol=1e-5, atol=1e-5)
        for i, r in zip(infos, infos_r):
            assert sorted(i) == sorted(r)
            for k, v in i.items():
                np.testing.assert_allclose(v, r[k], rtol=1e-5, atol=1e-5, err_msg=k)
        ends += int(done.sum())
    assert ends >= E and ours.get_attr("actions") == ["table"] * E and ours.env_is_wrapped(object) == [False] * E


def test_single_adapter_waypoint_actions_follow_the_gymnax_env(curves):
    """SemUAVGymEnv(actions="waypoint") steps as SemUAVEnv(actions="waypoint") with the same key chain."""
    import jax

    import semuav_jax
    from semuav_jax.actions import NUM_WAYPOINT_ACTIONS
    from semuav_jax.gym_adapter import SemUAVGymEnv

    g = SemUAVGymEnv(actions="waypoint", curves=curves, K=K)
    env, p = semuav_jax.make("SemUAV-v0", actions="waypoint", curves=curves, K=K)
    assert g.action_space.n == NUM_WAYPOINT_ACTIONS == 16
    obs_g, _ = g.reset(seed=3)
    key, k = jax.random.split(jax.random.key(3))
    obs_f, s = env.reset(k, p)
    for a in (0, 4, 7, 15, 2):
        obs_g, r_g, *_ = g.step(a)
        key, k = jax.random.split(key)
        obs_f, s, r_f, *_ = env.step(k, s, a, p)
        np.testing.assert_array_equal(obs_g, obs_f)
        assert r_g == float(r_f)
    for bad in (16, -1, 2.5):
        with pytest.raises(ValueError, match=r"action must be an integer in \[0, 15\]"):
            g.step(bad)
    with pytest.raises(ValueError, match="actions must be one of .*got 'speed'"):
        SemUAVGymEnv(actions="speed", curves=curves, K=K)


@pytest.mark.parametrize(
    "action, shown",
    [
        (True, "True"),
        (np.float32(2.0), "np.float32(2.0)"),
        (np.zeros((3, 3), np.int64), "int64 array of shape (3, 3)"),
        ("1", "'1'"),
    ],
)
def test_single_adapter_bad_action_type_is_one_line(curves, action, shown):
    """A bool, a float, an array or a string is not a Discrete action: one line naming it (no
    multi-line array repr); a bool is refused although Python counts it as an int."""
    from semuav_jax.gym_adapter import SemUAVGymEnv

    g = SemUAVGymEnv(curves=curves, K=K)
    g.reset(seed=0)
    with pytest.raises(ValueError, match=r"action must be an integer in \[0, 8\], got ") as err:
        g.step(action)
    assert str(err.value).endswith(shown) and "\n" not in str(err.value)


def test_ragged_vector_actions_are_one_line(curves):
    env = SemUAVVectorEnv(num_envs=E, curves=curves, K=K)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(4,\), got \[0, \[1, 2\], 3, 4\]$") as err:
        env.step([0, [1, 2], 3, 4])
    assert "\n" not in str(err.value)
