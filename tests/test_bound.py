"""The mean-PSNR upper bound (baselines/bound.py): budget by hand, exact knapsack, and that it bounds."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from baselines.bound import knapsack, peak_rate, psnr_bound, symbol_budget
from baselines.evaluate import evaluate, layouts
from semuav_jax import channel
from semuav_jax.params import make_params


@pytest.fixture(scope="module")
def shipped():
    return make_params()  # the DeepJSCC curves: not concave, not even monotone


@pytest.fixture(scope="module")
def keys():
    return jax.random.split(jax.random.PRNGKey(7), 64)


def _images(keys, params):
    return np.asarray(layouts(keys, params)[1])


def test_symbol_budget_by_hand(params):
    # MODEL.md section 2: right below the UAV theta = 90 deg, PL = 79.46 dB, R = 324.7 bit/s at 20 kHz
    p_los = 1 / (1 + 9.61 * np.exp(-0.16 * (90 - 9.61)))
    pl = 20 * np.log10(4 * np.pi * 2e9 * 100 / 3e8) + p_los * 1 + (1 - p_los) * 20
    assert pl == pytest.approx(79.46, abs=0.01)
    R0 = 20e3 * np.log2(1 + 1e-3 / (1e-9 * 10 ** (pl / 10)))
    assert R0 == pytest.approx(324.7, abs=0.1)
    assert symbol_budget(params) == pytest.approx(250 * 0.5 * R0 / 16, rel=1e-3)  # ≈ 2536.7
    assert symbol_budget(params) == pytest.approx(2536.7, abs=0.5)
    assert symbol_budget(params.replace(B=5e3)) == pytest.approx(2536.7 / 4, abs=0.2)


def test_snr_is_largest_right_below(params):
    r = np.linspace(0.0, np.sqrt(105.0**2 - 100.0**2), 20001)
    s = np.asarray(jax.jit(channel.snr)(jnp.asarray(r * r, jnp.float32), params.H, params.P_n, params))
    assert np.all(np.diff(s) <= 0.0)
    assert peak_rate(params) == pytest.approx(
        float(channel.rate(0.0, params.H, params.P_n, params.B, params)), rel=1e-5
    )


def _brute(c, budget):
    N, M1 = c.shape
    return max(
        sum(c[n, k] for n, k in enumerate(ks)) for ks in itertools.product(range(M1), repeat=N) if sum(ks) <= budget
    )


@pytest.mark.parametrize("N,M", [(1, 6), (3, 6), (4, 4)])
def test_knapsack_equals_brute_force(N, M):
    rng = np.random.default_rng(N * 10 + M)
    curves = rng.normal(size=(5, N, M + 1)).astype(np.float32) * 3.0  # non-concave, non-monotone
    for budget in range(N * M + 3):
        want = np.array([_brute(c, budget) for c in curves])
        np.testing.assert_allclose(knapsack(curves, budget), want, atol=1e-5)
        assert knapsack(curves[0], budget) == pytest.approx(want[0], abs=1e-5)


def test_knapsack_rejects_bad_input():
    with pytest.raises(ValueError, match="budget"):
        knapsack(np.zeros((2, 3)), -1)
    with pytest.raises(ValueError, match="curves"):
        knapsack(np.zeros(3), 1)


def test_keys_validated(params, shipped):
    with pytest.raises(ValueError, match="batch of PRNG keys"):
        psnr_bound(jax.random.PRNGKey(0), params)
    with pytest.raises(ValueError, match="batch of PRNG keys"):
        psnr_bound(np.zeros((4, 2), np.float32), params)
    typed = jax.random.split(jax.random.key(7), 64)
    np.testing.assert_allclose(psnr_bound(typed, shipped), psnr_bound(jax.random.key_data(typed), shipped))


def test_unbounded_budget_is_best_prefix(params, shipped, keys):
    # synthetic monotone curves: the full-latent mean C[i_n, M] (knapsack with the budget N·M)
    C = np.asarray(params.C)
    rows = C[np.random.default_rng(0).integers(0, len(C), (64, params.N))]
    np.testing.assert_allclose(knapsack(rows, params.N * params.M), rows[..., -1].sum(-1), rtol=1e-6)
    # shipped curves peak before M: the bound is the mean of max_k C[i_n, k] (a policy can stop there)
    p = shipped.replace(B=25e3)
    assert symbol_budget(p) >= p.N * p.M
    C, img = np.asarray(p.C), _images(keys, p)
    b = psnr_bound(keys, p)
    np.testing.assert_allclose(b, C[img].max(-1).mean(-1), atol=1e-5)
    assert np.all(b >= C[img, -1].mean(-1) - 1e-5)


def test_binds_at_low_bandwidth(shipped, keys):
    p = shipped.replace(B=5e3)
    full = np.asarray(p.C)[_images(keys, p), -1].mean(-1)
    assert np.all(psnr_bound(keys, p) < full)


def test_greedy_never_exceeds_bound(shipped, keys):
    for B in (5e3, 25e3):
        p = shipped.replace(B=B)
        achieved = evaluate("greedy", keys, p, v_b=18.0)["mean_psnr"]
        assert np.all(achieved <= psnr_bound(keys, p) + 1e-4)


def test_monotone_in_bandwidth(shipped, keys):
    bounds = np.stack([psnr_bound(keys, shipped.replace(B=B)) for B in (1e3, 3e3, 5e3, 10e3, 15e3, 20e3, 40e3)])
    assert np.all(np.diff(bounds, axis=0) >= -1e-5)
