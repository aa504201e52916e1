"""Shared fixtures: synthetic, monotone PSNR curves so simulator tests do not depend on DeepJSCC;
the options of a train.py run of seconds, and a child process that Ctrl-C reaches."""

import gc
import signal
import subprocess
from pathlib import Path

import jax
import pytest

from semuav_jax.curves import synthetic_curves
from semuav_jax.params import make_params

__all__ = ["synthetic_curves"]

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(autouse=True, scope="session")
def _reference_cache(tmp_path_factory):
    """The tests' cache of references (experiments.references) is their own, never the user's."""
    patch = pytest.MonkeyPatch()
    patch.setenv("SEMUAV_CACHE", str(tmp_path_factory.mktemp("semuav-cache")))
    yield
    patch.undo()


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """Drop JAX's compiled programs after each test module: every executable holds memory maps, and
    the whole suite in one process otherwise passes the kernel's vm.max_map_count (65530), where
    XLA's compiler segfaults (seen at test_tour with 433 fast tests)."""
    yield
    jax.clear_caches()
    gc.collect()


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


# train.py's options of a run that takes seconds (80 env steps)
TRAIN_RUN = {
    "num_envs": 4,
    "steps_per_chunk": 5,
    "total_steps": 80,
    "learning_starts": 32,
    "batch_size": 8,
    "segments": 2,
    "demo_steps": 8,  # the default agent learns from demonstrations: 8 vmapped steps of them
    "demo_batch": 4,
}


def train_options(**options: object) -> list[str]:
    """train.py's options of TRAIN_RUN with ``options`` (``eval_episodes=4``) changed or added, in that order."""
    return [a for k, v in (TRAIN_RUN | options).items() for a in (f"--{k.replace('_', '-')}", str(v))]


# the run of the waypoint agent (quicker to compile) on synthetic curves without an evaluation: what tests of the
# command's mechanics (run folder, faults, processes) train
TRAIN_TINY = ["--preset", "waypoint", "--curves", "synthetic", *train_options(eval_episodes=0, workers=1, demo_steps=0)]


def short_option_training(curves, actions: str) -> tuple:
    """A short training of an option agent (``actions``: option or mixed) run twice with the same
    key: (config, state, state again, chunk metrics)."""
    from semuav_jax.agents.config import DDQNConfig
    from semuav_jax.agents.trainer import make_train

    cfg = DDQNConfig(actions=actions, num_envs=8, steps_per_chunk=20, total_steps=8 * 20 * 3,
                     learning_starts=64, batch_size=16, buffer_size=4096, hidden=(16,), gamma=0.95)  # fmt: skip
    tr = make_train(cfg, make_params(curves, K=60))
    (ts, m), (ts2, _) = (jax.jit(tr.train)(jax.random.key(3)) for _ in range(2))
    return cfg, ts, ts2, m


def start_interruptible(cmd: list[str]) -> subprocess.Popen:
    """``cmd`` started in the repository's root with its output piped (text) and SIGINT at its
    default, as in a foreground shell: a test run in the background inherits SIGINT ignored, and
    Python then installs no KeyboardInterrupt handler."""
    return subprocess.Popen(
        cmd,
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )


# a semuav-sweep grid of seconds (2 bandwidths x 2 policies x 2 seeds), for test_distributed_results and _faults
GRID = {"episodes": 6, "seeds": [0, 1], "policies": ["greedy", "tsp@15"], "params": {"B": [5e3, 25e3], "K": 60}}
