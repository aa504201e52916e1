"""Minimal gymnax-compatible spaces (``Discrete``, ``Box``), so gymnax-style code runs without gymnax."""

from __future__ import annotations

import jax
import jax.numpy as jnp


class Discrete:
    """Integers 0 .. n - 1, as ``gymnax.environments.spaces.Discrete``."""

    def __init__(self, num_categories: int):
        self.n = num_categories
        self.shape = ()
        self.dtype = jnp.int32

    def sample(self, rng):
        return jax.random.randint(rng, self.shape, 0, self.n).astype(self.dtype)

    def contains(self, x):
        return jnp.logical_and(x >= 0, x < self.n)


class Box:
    """A box in R^shape, as ``gymnax.environments.spaces.Box``."""

    def __init__(self, low, high, shape: tuple, dtype=jnp.float32):
        self.low = low
        self.high = high
        self.shape = shape
        self.dtype = dtype

    def sample(self, rng):
        return jax.random.uniform(rng, self.shape, minval=self.low, maxval=self.high).astype(self.dtype)

    def contains(self, x):
        return jnp.logical_and(jnp.all(x >= self.low), jnp.all(x <= self.high))
