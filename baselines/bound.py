"""A cheap upper bound on the mean PSNR (eq. 8.1) that no policy can exceed.

Derivation (docs/model.md): in one slot the devices together receive Σ_n x_n R_n τ/β symbols
(eq. 3.7) with R_n = (B/k) log2(1 + SNR_n) (eqs. 2.6, 3.6); SNR does not depend on the band and
is largest right below the UAV, so Σ_n x_n R_n ≤ B log2(1 + SNR(0)) = R0 and the whole mission
(K slots) delivers at most S = K τ R0 / β symbols. With m_n ≤ M and Σ ⌊m_n⌋ ≤ ⌊S⌋, eqs. 3.8 and
8.1 give mean_psnr ≤ max (1/N) Σ_n C[i_n, k_n] over integers 0 ≤ k_n ≤ M with Σ k_n ≤ ⌊S⌋.

That maximum is a multiple-choice knapsack, solved exactly by a max-plus dynamic programme over
the devices (:func:`knapsack`); the curves are not concave (nor even monotone), so no greedy
shortcut. ``max over k_n ≤ M`` matters: a shipped curve often peaks before k = M, and a policy
can stop a device there by leaving its range, so the bound with S ≥ N·M is the mean of
max_k C[i_n, k], not of C[i_n, M].
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from baselines.evaluate import layouts
from semuav_jax import channel
from semuav_jax.control import range_radius
from semuav_jax.params import EnvParams, validate_params

R_GRID = 4097  # ground distances in [0, range radius] at which the largest SNR is taken


def peak_rate(params: EnvParams) -> float:
    """R0 = B log2(1 + max SNR) (eq. 2.6) over the ground distances where a device is in range
    (eq. 3.5); the SNR decreases with the distance, so the maximum is at r = 0 (a test checks it)."""
    r = np.linspace(0.0, float(range_radius(params)), R_GRID)
    return float(np.max(np.asarray(_rates(jnp.asarray(r * r, jnp.float32), params), np.float64)))


@jax.jit
def _rates(r2: ArrayLike, params: EnvParams) -> jax.Array:
    return channel.rate(r2, params.H, params.P_n, params.B, params)


def symbol_budget(params: EnvParams) -> float:
    """S = K τ R0 / β: the most symbols all devices together can receive in one mission."""
    validate_params(params)
    return params.K * float(params.tau) * peak_rate(params) / float(params.beta)


def _budget(params: EnvParams) -> int:
    """⌊S⌋ widened by the float32 error of the env's counters (≤ one rounding of m ≤ M per
    device-slot, and a relative 1e-4 on the rate: eager and compiled float32 differ by ~4e-6),
    capped at N·M where it stops binding."""
    S = symbol_budget(params)
    slack = 1e-4 * S + params.N * params.K * params.M * 2.0**-24
    return int(min(np.floor(S + slack), params.N * params.M))


def _profile(c: np.ndarray, cap: int) -> np.ndarray:
    """F[e, b] = max Σ_j c[e, j, k_j] over Σ_j k_j = b exactly (each k_j ≤ M), b ≤ min(cap, n·M).

    Max-plus convolution one device at a time, looping over the shorter of the two axes
    (the device's k, or the budget already spent) and vectorized over episodes and the other.
    """
    E, n, M1 = c.shape
    f = np.zeros((E, 1), c.dtype)
    for j in range(n):
        cj = c[:, j]
        L_f = f.shape[1]
        L = min(cap, L_f - 1 + M1 - 1) + 1
        out = np.full((E, L), -np.inf, c.dtype)
        tmp = np.empty((E, max(L_f, M1)), c.dtype)
        if L_f >= M1:  # loop over the device's k
            for k in range(min(M1, L)):
                s = min(L_f, L - k)
                np.add(f[:, :s], cj[:, k : k + 1], out=tmp[:, :s])
                np.maximum(out[:, k : k + s], tmp[:, :s], out=out[:, k : k + s])
        else:  # loop over the budget b already spent
            for b in range(min(L_f, L)):
                s = min(M1, L - b)
                np.add(cj[:, :s], f[:, b : b + 1], out=tmp[:, :s])
                np.maximum(out[:, b : b + s], tmp[:, :s], out=out[:, b : b + s])
        f = out
    return f


def knapsack(curves: np.ndarray, budget: int) -> np.ndarray:
    """max Σ_n curves[..., n, k_n] over integers 0 ≤ k_n ≤ M with Σ_n k_n ≤ budget, exactly.

    ``curves`` (N, M + 1) or (E, N, M + 1): the curve of each device (any shape, not concave).
    Returns the (E,) sums (a scalar for one episode), in float32 like the env's C (rounding
    ~1e-5 of a sum). First c[k] → max_{k' ≤ k} c[k'] (fewer symbols are allowed), so the
    optimum uses exactly W = min(budget, N·M) symbols, or equally leaves out exactly N·M − W:
    the DP runs on whichever of the two is smaller (the curves read backwards for the second).
    Meet in the middle: exact-sum profiles of the two halves of the devices, then the best
    split of W between them.
    """
    c = np.asarray(curves, np.float32)
    if c.ndim not in (2, 3) or c.shape[-1] < 1 or c.shape[-2] < 1:
        raise ValueError(f"curves must have shape (N, M + 1) or (E, N, M + 1), got {c.shape}")
    if int(budget) != budget or budget < 0:
        raise ValueError(f"budget must be an integer >= 0, got {budget}")
    single = c.ndim == 2
    c = np.maximum.accumulate(c[None] if single else c, axis=-1)
    N, M = c.shape[1], c.shape[2] - 1
    W = int(min(budget, N * M))
    if N * M - W < W:  # leave out exactly N·M − W symbols (the curves are non-decreasing)
        c, W = np.ascontiguousarray(c[:, :, ::-1]), N * M - W
    h = (N + 1) // 2
    fa, fb = _profile(c[:, :h], W), _profile(c[:, h:], W)
    lo, hi = max(0, W - (fb.shape[1] - 1)), min(W, fa.shape[1] - 1)
    b = np.arange(lo, hi + 1)
    total = np.max(fa[:, b] + fb[:, W - b], axis=1)
    return total[0] if single else total


def _check_keys(keys: ArrayLike) -> jax.Array:
    keys = jnp.asarray(keys)
    typed = jax.dtypes.issubdtype(keys.dtype, jax.dtypes.prng_key)
    if not ((typed and keys.ndim == 1) or (not typed and keys.ndim == 2 and keys.dtype == jnp.uint32)):
        raise ValueError(f"keys must be a batch of PRNG keys (E, 2) uint32 or (E,) typed, got {keys.dtype}{keys.shape}")
    if typed and jax.random.key_data(keys).shape[-1] == 2:  # threefry: the same keys as raw (E, 2)
        keys = jax.random.key_data(keys)  # so both forms share one compiled layout program
    return keys


def psnr_bound(keys: jax.Array, params: EnvParams) -> np.ndarray:
    """(E,) per-episode upper bound (dB) on the final mean PSNR (eq. 8.1) of any policy on the
    episodes run with ``keys`` (their layouts' images; see the module docstring)."""
    keys = _check_keys(keys)
    validate_params(params)
    _, img = layouts(keys, params)
    rows = np.asarray(params.C, np.float64)[np.asarray(img)]  # (E, N, M + 1)
    return knapsack(rows, _budget(params)) / params.N
