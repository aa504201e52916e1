"""MODEL.md section 2 by hand and against the float64 NumPy transcription."""

import math

import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from reference_numpy import a2g_path_loss_db, a2g_rate, params_dict

from semuav_jax import channel


def test_device_right_below_uav(params):
    # theta = 90 deg: P_LoS = 1/(1 + 9.61 exp(-0.16 * 80.39)) ~ 0.99997
    # FSPL = 20 log10(4 pi 2e9 100 / 3e8) = 78.463 dB; + ~1 dB LoS excess -> 79.463 dB
    fspl = 20 * math.log10(4 * math.pi * 2e9 * 100 / 3e8)
    assert abs(fspl - 78.4627) < 1e-3
    pl = float(channel.path_loss_db(0.0, 100.0, params))
    assert abs(pl - 79.463) < 0.01
    snr_db = 10 * math.log10(float(channel.snr(0.0, 100.0, 1e-3, params)))
    assert abs(snr_db - (-19.463)) < 0.01  # 0 dBm - 79.46 dB - (-60 dBm noise)
    r = float(channel.rate(0.0, 100.0, 1e-3, 20e3, params))
    assert abs(r - 324.7) < 0.5  # 20 kHz * log2(1 + 0.01132)
    assert abs(r * 0.5 / 16 - 10.15) < 0.02  # ~10 symbols per slot


def test_elevation_matches_atan2_everywhere():
    r = np.concatenate([np.linspace(0, 3000, 30001), np.geomspace(1e-4, 1e6, 2001)])
    for dh in (100.0, 75.0, 3.0, -20.0):
        got = np.asarray(channel.elevation_deg(jnp.asarray(r**2, jnp.float32), jnp.float32(dh)))
        np.testing.assert_allclose(got, np.degrees(np.arctan2(dh, r)), atol=5e-5)


@settings(max_examples=60, deadline=None)
@given(r=st.floats(0, 1500), dh=st.floats(1, 300), bw=st.floats(1e3, 1e6), power=st.floats(1e-4, 10))
def test_rate_matches_reference(params, r, dh, bw, power):
    p = params_dict(params)
    pl = float(channel.path_loss_db(jnp.float32(r * r), jnp.float32(dh), params))
    assert abs(pl - a2g_path_loss_db(r, dh, p)) < 1e-3
    got = float(channel.rate(jnp.float32(r * r), jnp.float32(dh), power, bw, params))
    ref = a2g_rate(r, dh, power, bw, p)
    assert abs(got - ref) <= 1e-4 * ref + 1e-3


@settings(max_examples=40, deadline=None)
@given(r1=st.floats(0, 1000), r2=st.floats(0, 1000))
def test_rate_decreases_with_distance(params, r1, r2):
    lo, hi = sorted((r1, r2))
    rate = lambda r: float(channel.rate(jnp.float32(r * r), 100.0, 1e-3, 20e3, params))
    assert rate(lo) >= rate(hi) * (1 - 1e-5)
