"""The core controller (semuav_jax/control.py, docs/model.md eqs. 7.1-7.5): values by hand."""

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from semuav_jax.control import (
    airspace_cap,
    approach_speed,
    home_command,
    speed_command,
    time_home,
    time_to_pass,
    time_via,
)

V_B = 8.9


def time_home_by_hand(q, v, speed, cruise, a=5.0, r=15.0, q_fin=(1000.0, 300.0)):
    """Eq. 7.5 transcribed from docs/model.md."""
    diff = np.subtract(q_fin, q)
    dist = np.linalg.norm(diff)
    u = diff / dist
    along = np.dot(v, u)
    side = np.subtract(v, along * u)
    c = 2 * 0.25 * a  # the approach brakes with a quarter of a_max
    over = max(along**2 - min(speed**2, c * dist), 0.0)  # faster than the approach speed sqrt(c d)
    d = dist + (side @ side + min(along, 0.0) ** 2 + 2 * over) / (2 * a)  # drift while turning
    d0 = cruise**2 / c  # where the braking profile sqrt(c d) reaches the cruise speed
    brake = 2 * (np.sqrt(np.clip(d, r, d0)) - np.sqrt(r)) / np.sqrt(c)
    return np.max(np.abs(cruise * u - np.asarray(v))) / a + max(d - d0, 0.0) / cruise + brake


def test_speed_command_by_hand(params):
    q = jnp.array([0.0, 0.0])
    # from rest towards +x: (8.9 - 0) / 0.5 = 17.8 -> clipped to a_max = 5
    np.testing.assert_allclose(speed_command(q, jnp.zeros(2), jnp.array([100.0, 0.0]), V_B, params), [5.0, 0.0])
    # cruising at v_b towards the target: no command
    np.testing.assert_allclose(
        speed_command(q, jnp.array([V_B, 0.0]), jnp.array([100.0, 0.0]), V_B, params), [0.0, 0.0]
    )
    # 0.5 m/s short: (8.9 - 8.4) / 0.5 = 1.0
    np.testing.assert_allclose(
        speed_command(q, jnp.array([8.4, 0.0]), jnp.array([100.0, 0.0]), V_B, params), [1.0, 0.0], rtol=1e-5
    )
    # a right-angle turn: (-17.8, 17.8) -> (-5, 5)
    np.testing.assert_allclose(
        speed_command(q, jnp.array([V_B, 0.0]), jnp.array([0.0, 100.0]), V_B, params), [-5.0, 5.0]
    )
    # at the target itself: brake, no NaN
    np.testing.assert_allclose(speed_command(q, jnp.array([1.0, -2.0]), q, V_B, params), [-2.0, 4.0])


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.floats(-2000, 2000), min_size=6, max_size=6), st.floats(0.1, 40.0), st.sampled_from([None, 0.0, 30.0])
)
def test_speed_command_never_exceeds_a_max(params, xs, v_b, margin):
    p = params if margin is None else params.replace(airspace_margin=margin)
    a = speed_command(jnp.array(xs[:2]), jnp.array(xs[2:4]) / 50.0, jnp.array(xs[4:]), v_b, p)
    assert np.all(np.isfinite(np.asarray(a))) and np.all(np.abs(np.asarray(a)) <= params.a_max)


def test_airspace_cap_by_hand(params):
    v = jnp.array([25.0, -25.0])
    # no margin set: no cap
    np.testing.assert_array_equal(airspace_cap(jnp.array([990.0, 300.0]), v, params), v)
    p = params.replace(airspace_margin=0.0)
    # 10 m from x = 1000: w^2 / 10 + 0.75 w = 10 -> w = sqrt(3.75^2 + 100) - 3.75 = 6.930;
    # 300 m from y = 0 the cap is sqrt(3.75^2 + 3000) - 3.75 = 51.2 m/s, so -25 stays
    np.testing.assert_allclose(airspace_cap(jnp.array([990.0, 300.0]), v, p), [6.930, -25.0], atol=1e-3)
    # 20 m from y = 0: sqrt(3.75^2 + 200) - 3.75 = 10.881 m/s
    np.testing.assert_allclose(airspace_cap(jnp.array([500.0, 20.0]), v, p), [25.0, -10.881], atol=1e-3)
    # beyond the limit the cap is 0 towards it, free away from it
    np.testing.assert_allclose(airspace_cap(jnp.array([1003.0, 300.0]), jnp.array([3.0, 0.0]), p), [0.0, 0.0])
    np.testing.assert_allclose(airspace_cap(jnp.array([1003.0, 300.0]), jnp.array([-3.0, 0.0]), p), [-3.0, 0.0])


def test_approach_speed_by_hand(params):
    # sqrt(2 * 0.25 * 5 * d) = sqrt(2.5 d): 5 m/s at 10 m, capped at the speed asked for
    assert float(approach_speed(10.0, 25.0, params)) == pytest.approx(5.0)
    assert float(approach_speed(1000.0, 8.9, params)) == pytest.approx(8.9)
    assert float(approach_speed(-1.0, 8.9, params)) == 0.0


def test_time_to_pass_by_hand(params):
    # from rest at q0 through (500, 300) at 8.9 m/s: turn 8.9 / 5 = 1.78 s, then 500 / 8.9 = 56.18 s
    assert float(time_to_pass(params.q0, jnp.zeros(2), jnp.array([500.0, 300.0]), V_B, params)) == pytest.approx(
        1.78 + 500 / 8.9, rel=1e-6
    )
    # flying +y at 10 m/s towards a point 300 m along +x: turn max(8.9, 10) / 5 = 2 s, drift 100 / 10 = 10 m
    t = time_to_pass(jnp.array([0.0, 0.0]), jnp.array([0.0, 10.0]), jnp.array([300.0, 0.0]), V_B, params)
    assert float(t) == pytest.approx(2.0 + 310.0 / 8.9, rel=1e-6)


def test_time_home_by_hand(params):
    th = lambda q, v, s: float(time_home(jnp.array(q), jnp.array(v), s, params))
    # at 8.9 m/s from (500, 300) along +x: no turn; cruise (500 - 31.684) / 8.9 = 52.620 s; brake
    # 2 (sqrt(31.684) - sqrt(15)) / sqrt(2.5) = 2.221 s (d0 = 8.9^2 / 2.5 = 31.684 m)
    assert th([500.0, 300.0], [8.9, 0.0], 8.9) == pytest.approx(52.620 + 2.221, abs=1e-3)
    for q, v, s in (
        ([120.0, 40.0], [-20.0, 7.0], 12.0),
        ([980.0, 330.0], [15.0, 20.0], 25.0),
        ([700.0, 590.0], [3.0, 1.0], 8.9),
        ([950.0, 300.0], [25.0, 0.0], 20.0),
    ):
        assert th(q, v, s) == pytest.approx(time_home_by_hand(q, v, s, s), rel=1e-5)


def test_time_via_by_hand(params):
    """Eqs. 7.4 + 7.5: from rest at q0 through (500, 300) at 8.9 m/s (1.78 + 500 / 8.9 s), then home
    leaving it at 8.9 m/s along +x (52.620 + 2.221 s, as above), or from rest with ``stop``."""
    p, rest = jnp.array([500.0, 300.0]), jnp.zeros(2)
    to_p = 1.78 + 500 / 8.9
    assert float(time_via(params.q0, rest, p, V_B, params)) == pytest.approx(to_p + 52.620 + 2.221, abs=1e-3)
    home = time_home_by_hand([500.0, 300.0], [0.0, 0.0], V_B, V_B)
    assert float(time_via(params.q0, rest, p, V_B, params, stop=True)) == pytest.approx(to_p + home, rel=1e-5)


def test_home_command_brakes_into_the_disk(params):
    # 10 m before q_fin at 20 m/s: approach speed sqrt(2.5 * 10) = 5 m/s, so brake with a_max in x
    np.testing.assert_allclose(
        home_command(jnp.array([990.0, 300.0]), jnp.array([20.0, 0.0]), 25.0, params), [-5.0, 0.0]
    )
