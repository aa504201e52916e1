"""The named key streams: layouts used to choose settings never serve to report results.

Each stream is ``jax.random.split(jax.random.PRNGKey(SEED), E)`` with its own root seed, so
episodes of different streams are independent draws. Training seeds are 0, 1, 2, ... (train.py).
"""

import jax

VALIDATION_SEED = 20_261  # choosing settings: the tuned baseline speed v_b*, the planner's constants
TEST_SEED = 31_337  # reporting: docs/baselines.md and every comparison against the baselines


def episode_keys(seed: int, episodes: int):
    """The first ``episodes`` keys of the stream ``seed``."""
    return jax.random.split(jax.random.PRNGKey(seed), episodes)
