"""The environment's state (MODEL.md section 3): what ``env.transition`` carries from slot to slot.

Its own room so that the parts of a slot (``actions``, ``observation``, ``reward``) read it
without importing the environment that composes them; ``semuav_jax.env`` hands it on.
"""

from __future__ import annotations

import jax
from flax import struct


@struct.dataclass
class EnvState:
    """State at the end of slot t (MODEL.md section 3)."""

    q: jax.Array  # (2,) UAV ground position, m
    v: jax.Array  # (2,) velocity, m/s
    a_prev: jax.Array  # (2,) last command a[t] (clipped), still acting during the next delay
    t: jax.Array  # slot index, int32
    m: jax.Array  # (N,) symbols received, real-valued
    phi: jax.Array  # (N,) PSNR of each device's image, dB
    x: jax.Array  # (N,) bool, transmitted during slot t
    dev_pos: jax.Array  # (N, 2) device positions
    dev_img: jax.Array  # (N,) image index per device
    delay: jax.Array  # command delay of slot t, s
    arrived: jax.Array  # bool
    done: jax.Array  # bool: arrived or t == K
    ret: jax.Array  # return accumulated so far

    def renumbered(self, order: jax.Array) -> EnvState:
        """The same state with device i the former device ``order[i]`` (a device's index carries
        no meaning: the BS may number them as it likes, e.g. along a path)."""
        return self.replace(**{f: getattr(self, f)[order] for f in DEVICE_FIELDS})


DEVICE_FIELDS = ("m", "phi", "x", "dev_pos", "dev_img")  # the fields with a leading device axis
