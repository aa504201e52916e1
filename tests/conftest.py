"""Shared fixtures: synthetic, monotone PSNR curves so simulator tests do not depend on DeepJSCC."""

import pytest

from semuav_jax.curves import synthetic_curves
from semuav_jax.params import make_params

__all__ = ["synthetic_curves"]


@pytest.fixture(scope="session")
def curves():
    return synthetic_curves()


@pytest.fixture(scope="session")
def curves_file(tmp_path_factory, curves):
    """The synthetic curves as a file, for the commands' --curves."""
    from semuav_jax.curves import save_curves

    return str(save_curves(tmp_path_factory.mktemp("c") / "curves.npz", curves, {"source": "synthetic"}))


@pytest.fixture(scope="session")
def params(curves):
    return make_params(curves)


# train.py options of a run that takes seconds (synthetic curves, 80 env steps, no evaluation)
TRAIN_TINY = [
    "--curves",
    "synthetic",
    "--num-envs",
    "4",
    "--steps-per-chunk",
    "5",
    "--total-steps",
    "80",
    "--learning-starts",
    "32",
    "--batch-size",
    "8",
    "--segments",
    "2",
    "--eval-episodes",
    "0",
    "--workers",
    "1",
]


# a semuav-sweep grid of seconds (2 bandwidths x 2 policies x 2 seeds), for test_distributed_results and _faults
GRID = {"episodes": 6, "seeds": [0, 1], "policies": ["greedy", "tsp@15"], "params": {"B": [5e3, 25e3], "K": 60}}
