"""DeepJSCC in flax: model, training, PSNR curves C[i, k] (MODEL.md section 9).

Run ``semuav-jscc --help`` for the train / curves / figure commands.
"""

from semuav_jax.jscc.model import (
    BITS_PER_SYMBOL,
    IMAGE_SHAPE,
    IQ_CLIP,
    LATENT_SHAPE,
    DeepJSCC,
    M,
    awgn,
    power_normalize,
    prefix_mask,
    quantize_iq,
    truncate,
)

__all__ = [
    "BITS_PER_SYMBOL",
    "IMAGE_SHAPE",
    "IQ_CLIP",
    "LATENT_SHAPE",
    "M",
    "DeepJSCC",
    "awgn",
    "power_normalize",
    "prefix_mask",
    "quantize_iq",
    "truncate",
]
