"""Shared fixtures: synthetic, monotone PSNR curves so simulator tests do not depend on DeepJSCC."""

import numpy as np
import pytest

from semuav_jax.params import make_params


def synthetic_curves(images: int = 8, M: int = 256) -> np.ndarray:
    """Monotone test curves: 10 dB at k = 0 rising to about 30 dB at k = M (not DeepJSCC's)."""
    k = np.arange(M + 1)
    rows = [10.0 + (20.0 + i) * (1.0 - np.exp(-k / (40.0 + 5 * i))) for i in range(images)]
    return np.stack(rows).astype(np.float32)


@pytest.fixture(scope="session")
def curves():
    return synthetic_curves()


@pytest.fixture(scope="session")
def params(curves):
    return make_params(curves)
