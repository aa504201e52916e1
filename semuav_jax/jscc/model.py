"""Convolutional DeepJSCC with an importance-ordered latent (MODEL.md section 9).

A 32x32x3 image in [0, 1] maps to ``M = 256`` complex symbols (ratio 1/6). The latent is an
8x8x8 real tensor flattened channel-major (all 64 positions of channel 0 first, then channel 1,
...), and consecutive real pairs form the I/Q parts of one complex symbol, so that every prefix
of the symbol sequence covers the whole image.
"""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp

IMAGE_SHAPE = (32, 32, 3)
LATENT_SHAPE = (8, 8, 8)
M = LATENT_SHAPE[0] * LATENT_SHAPE[1] * LATENT_SHAPE[2] // 2
BITS_PER_SYMBOL = 16
IQ_CLIP = 4.0


def latent_to_symbols(z: jax.Array) -> jax.Array:
    """(B, 8, 8, 8) real latent -> (B, M) complex symbols, flattened channel-major."""
    r = jnp.transpose(z, (0, 3, 1, 2)).reshape(z.shape[0], M, 2)
    return r[..., 0] + 1j * r[..., 1]


def symbols_to_latent(s: jax.Array) -> jax.Array:
    """Inverse of :func:`latent_to_symbols`: (B, M) complex -> (B, 8, 8, 8) real."""
    h, w, c = LATENT_SHAPE
    r = jnp.stack([s.real, s.imag], axis=-1).reshape(s.shape[0], c, h, w)
    return jnp.transpose(r, (0, 2, 3, 1))


def received_plane(s: jax.Array) -> jax.Array:
    """(B, 8, 8, 8) plane, 1 at the latent entries of the received (non-zero) symbols, else 0."""
    return symbols_to_latent((s != 0) * (1.0 + 1.0j))


def power_normalize(s: jax.Array, mask: jax.Array | None = None) -> jax.Array:
    """Scale each row so its (kept) symbols have unit average complex power; masked symbols -> 0."""
    if mask is None:
        mask = jnp.ones(s.shape, dtype=bool)
    n = jnp.sum(mask, axis=-1, keepdims=True)
    p = jnp.sum(jnp.where(mask, jnp.abs(s) ** 2, 0.0), axis=-1, keepdims=True) / jnp.maximum(n, 1)
    return jnp.where(mask, s / jnp.sqrt(p + 1e-12), 0.0)


def prefix_mask(k: jax.Array, num_symbols: int = M) -> jax.Array:
    """(B,) kept counts -> (B, num_symbols) boolean mask of the first k symbols."""
    return jnp.arange(num_symbols)[None, :] < jnp.asarray(k)[:, None]


def truncate(s: jax.Array, k: jax.Array) -> jax.Array:
    """Keep the first k[b] symbols of row b, renormalized to unit power; zero the tail."""
    return power_normalize(s, prefix_mask(k, s.shape[-1]))


def complex_noise(key: jax.Array, shape: tuple[int, ...], snr_db: float) -> jax.Array:
    """Circular complex Gaussian noise of variance 10^(-snr/10) (unit signal power)."""
    sigma = jnp.sqrt(10.0 ** (-snr_db / 10.0) / 2.0)
    kr, ki = jax.random.split(key)
    return sigma * (jax.random.normal(kr, shape) + 1j * jax.random.normal(ki, shape))


def awgn(key: jax.Array, s: jax.Array, snr_db: float, mask: jax.Array) -> jax.Array:
    """Add complex AWGN of variance 10^(-snr/10) to the transmitted (masked) symbols only."""
    return jnp.where(mask, s + complex_noise(key, s.shape, snr_db), 0.0)


def quantize_iq(s: jax.Array, bits: int = BITS_PER_SYMBOL // 2, clip: float = IQ_CLIP) -> jax.Array:
    """Uniform ``bits``-bit quantization of I and Q each over [-clip, clip] (2^bits levels)."""
    step = 2.0 * clip / (2**bits - 1)

    def q(x: jax.Array) -> jax.Array:
        return jnp.round((jnp.clip(x, -clip, clip) + clip) / step) * step - clip

    return q(s.real) + 1j * q(s.imag)


class Encoder(nn.Module):
    """32x32x3 -> 8x8x8 real latent (before power normalization)."""

    width: int = 32

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        w = self.width
        x = nn.gelu(nn.Conv(w // 2, (3, 3))(x * 2.0 - 1.0))
        x = nn.gelu(nn.Conv(w, (3, 3), strides=2)(x))
        x = x + nn.Conv(w, (3, 3))(nn.gelu(nn.Conv(w, (3, 3))(x)))
        x = nn.gelu(nn.Conv(w, (3, 3), strides=2)(x))
        x = x + nn.Conv(w, (3, 3))(nn.gelu(nn.Conv(w, (3, 3))(x)))
        return nn.Conv(LATENT_SHAPE[2], (3, 3))(x)


def depth_to_space(x: jax.Array, r: int = 2) -> jax.Array:
    """(B, H, W, C*r*r) -> (B, H*r, W*r, C) pixel shuffle."""
    b, h, w, c = x.shape
    x = x.reshape(b, h, w, r, r, c // (r * r))
    return jnp.transpose(x, (0, 1, 3, 2, 4, 5)).reshape(b, h * r, w * r, c // (r * r))


class Decoder(nn.Module):
    """8x8x8 received latent -> 32x32x3 image in [0, 1]; with ``mask_input`` the decoder also
    sees which latent entries were received (an 8x8x8 0/1 plane)."""

    width: int = 32

    @nn.compact
    def __call__(self, z: jax.Array, mask: jax.Array | None = None) -> jax.Array:
        w = self.width
        if mask is not None:
            z = jnp.concatenate([z, mask], axis=-1)
        x = nn.gelu(nn.Conv(w, (3, 3))(z))
        x = x + nn.Conv(w, (3, 3))(nn.gelu(nn.Conv(w, (3, 3))(x)))
        x = nn.gelu(depth_to_space(nn.Conv(4 * w, (3, 3))(x)))
        x = x + nn.Conv(w, (3, 3))(nn.gelu(nn.Conv(w, (3, 3))(x)))
        x = nn.gelu(depth_to_space(nn.Conv(2 * w, (3, 3))(x)))
        return nn.sigmoid(nn.Conv(3, (3, 3))(x))


class DeepJSCC(nn.Module):
    """Encoder + decoder; the channel sits between :meth:`encode` and :meth:`decode`."""

    width: int = 32
    mask_input: bool = False

    def setup(self) -> None:
        self.encoder = Encoder(self.width)
        self.decoder = Decoder(self.width)

    def encode(self, x: jax.Array) -> jax.Array:
        """Images (B, 32, 32, 3) in [0, 1] -> (B, M) complex symbols of unit average power."""
        return power_normalize(latent_to_symbols(self.encoder(x)))

    def decode(self, s: jax.Array) -> jax.Array:
        """Received (B, M) complex symbols (tail zero-padded) -> images in [0, 1]. The received
        entries are the non-zero ones: neither channel yields an exact zero (8-bit I/Q levels
        are odd multiples of half a step, AWGN is continuous)."""
        mask = received_plane(s) if self.mask_input else None
        return self.decoder(symbols_to_latent(s), mask)

    def __call__(self, x: jax.Array, k: jax.Array, key: jax.Array, snr_db: float) -> jax.Array:
        """Encode, keep the first k symbols (renormalized), AWGN, zero-pad, decode."""
        mask = prefix_mask(k)
        return self.decode(awgn(key, truncate(self.encode(x), k), snr_db, mask))
