"""Shared fixtures: synthetic, monotone PSNR curves so simulator tests do not depend on DeepJSCC."""

import pytest

from semuav_jax.curves import synthetic_curves
from semuav_jax.params import make_params

__all__ = ["synthetic_curves"]


@pytest.fixture(scope="session")
def curves():
    return synthetic_curves()


@pytest.fixture(scope="session")
def params(curves):
    return make_params(curves)
