"""Values that used to pass validation: actions, make_params, PSNR curves, gymnasium seeds, one-sample intervals."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from semuav_jax import env as E
from semuav_jax.curves import validate_curves
from semuav_jax.params import make_params
from semuav_jax.stats import mean_ci, pm


@pytest.fixture(scope="module")
def table_env():
    env, p = E.make(E.ENV_ID)
    _, s = env.reset(jax.random.key(0), p)
    return env, p, s


@pytest.mark.parametrize("action", [9, 99, -1, 3.0, None, True, np.array([1, 2])])
def test_step_refuses_an_action_that_is_not_an_integer_in_range(table_env, action):
    env, p, s = table_env
    with pytest.raises(ValueError, match=r"action must be an integer in \[0, 9\)"):
        env.step(jax.random.key(1), s, action, p)


def test_waypoint_action_out_of_range_is_refused_and_traced_ones_are_not_valid(curves):
    env, p = E.make(E.ENV_ID, actions="waypoint", curves=curves)
    _, s = env.reset(jax.random.key(0), p)
    n = env.num_actions
    with pytest.raises(ValueError, match="action must be an integer"):
        env.step(jax.random.key(1), s, -1, p)
    valid = jax.jit(lambda a: env.step(jax.random.key(1), s, a, p)[5]["valid"])
    assert bool(valid(jnp.int32(n - 1))) and not bool(valid(jnp.int32(n))) and not bool(valid(jnp.int32(-1)))


def test_step_refuses_a_state_of_another_n(table_env, curves):
    env, _, s = table_env
    _, p5 = E.make(E.ENV_ID, N=5, curves=curves)
    with pytest.raises(ValueError, match="state has 10 devices but params N = 5"):
        env.step(jax.random.key(1), s, 3, p5)


@pytest.mark.parametrize(
    "kw, msg",
    [
        ({"B": [1e3, 2e3]}, "B must be a scalar"),
        ({"a_max": 1e30}, "a_max must be below"),
        ({"v_max": 1e20}, "v_max must be below"),
        ({"Lx": 1e20}, "Lx must be below"),
        ({"los_a": -1.0}, "los_a must be > 0"),
        ({"los_b": 0.0}, "los_b must be > 0"),
        ({"eta_los": -1.0}, "eta_los must be >= 0"),
        ({"eta_nlos": -3.0}, "eta_nlos must be >= 0"),
        ({"N": 5, "device_pos": np.full((10, 2), 100.0)}, "N = 5 disagrees with device_pos"),
        ({"device_pos": np.array([1.0, 2.0])}, r"device_pos must have shape \(N, 2\)"),
    ],
)
def test_make_params_refuses(curves, kw, msg):
    with pytest.raises(ValueError, match=msg):
        make_params(curves, **kw)


def test_a_max_at_the_bound_still_moves_the_uav(curves):
    """1e18 m/s^2 passes (its square is finite in float32) and the UAV moves: the cap of eq. 3.3 holds."""
    from semuav_jax.kinematics import speed_cap

    p = make_params(curves, a_max=1e18)
    v = speed_cap(jnp.zeros(2), jnp.array([1e18, 0.0]) * p.tau, p)
    np.testing.assert_allclose(np.asarray(v), [p.v_max, 0.0], rtol=1e-6)


def test_curves_below_zero_db_are_refused(curves):
    C = np.array(curves, np.float32)
    C[0, 0] = -0.5
    with pytest.raises(ValueError, match="below 0 dB"):
        validate_curves(C)


@pytest.mark.parametrize("seed", [2**32, 2**64, -1, 1.5, True])
def test_gymnasium_seeds_outside_the_key_range_are_refused(seed):
    from semuav_jax.gym_adapter import SemUAVGymEnv

    with pytest.raises(ValueError, match=r"seed must be an integer in \[0, 2\*\*32\)"):
        SemUAVGymEnv().reset(seed=seed)


def test_one_sample_has_no_interval():
    assert mean_ci([3.0]) == (3.0, None) and pm(None) == "± n/a"
    m, h = mean_ci([1.0, 3.0])
    assert m == 2.0 and h == pytest.approx(12.706 * 1.0, rel=1e-4) and pm(h) == "± 12.71"  # t_0.975(1) * s / sqrt 2
