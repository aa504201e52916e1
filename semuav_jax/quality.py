"""PSNR lookup of MODEL.md section 3, step 5 (eq. 3.8 in docs/model.md)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike


def psnr(C: jax.Array, img: ArrayLike, m: ArrayLike) -> jax.Array:
    """Eq. 3.8: phi = C[img, floor(m)], m the real-valued symbol counter clipped to [0, M]."""
    M = C.shape[-1] - 1
    k = jnp.clip(jnp.floor(m).astype(jnp.int32), 0, M)
    return C.reshape(-1)[img * (M + 1) + k]
