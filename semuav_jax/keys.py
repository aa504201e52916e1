"""The named key streams: layouts used to choose settings never serve to report results.

Each stream is ``jax.random.split(jax.random.PRNGKey(SEED), E)`` with its own root seed, so
episodes of different streams are independent draws. Training seeds are 0, 1, 2, ... (train.py).
"""

from __future__ import annotations

import jax

VALIDATION_SEED = 20_261  # choosing settings: v_b*, the planner's constants, the agent's hyperparameters
TEST_SEED = 53_113  # reporting: docs/baselines.md, docs/ddqn.md, docs/RESULTS.md (CHANGELOG: why not 31 337)


def episode_keys(seed: int, episodes: int) -> jax.Array:
    """The first ``episodes`` keys of the stream ``seed``."""
    return jax.random.split(jax.random.PRNGKey(seed), episodes)
