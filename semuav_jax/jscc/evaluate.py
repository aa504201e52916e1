"""PSNR curves C[i, k] of the trained DeepJSCC and the figure (MODEL.md section 9).

For test image i and k = 0..M: the transmitter keeps the first k symbols, renormalized to unit
average power (as in training), quantizes I and Q to 8 bits each over [-4, 4]; the receiver
zero-pads the tail and decodes (no noise). PSNR is that of the decoded image rounded to 8 bits.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import serialization

from semuav_jax.curves import default_curves_path, load_curves, save_curves, validate_curves
from semuav_jax.io import atomic_write, check_writable_folder, save_figure
from semuav_jax.jscc import data
from semuav_jax.jscc.model import BITS_PER_SYMBOL, IMAGE_SHAPE, IQ_CLIP, DeepJSCC, M, prefix_mask, quantize_iq, truncate
from semuav_jax.jscc.train import load_checkpoint, load_config, make_optimizer, model_of

DEFAULT_MODEL = "deepjscc.msgpack"
FRACTIONS = {"0": 0, "1/10": M // 10, "1/4": M // 4, "1/2": M // 2, "1": M}


def default_model_path() -> Path:
    return default_curves_path().parent / DEFAULT_MODEL


def model_blob(params: Any, model: DeepJSCC) -> bytes:
    """The model file's bytes: params (+ the module's fields) as flax msgpack."""
    arch = {"width": model.width, "mask_input": model.mask_input}
    return serialization.msgpack_serialize({**arch, "params": jax.device_get(params)})


def load_model(path: str | os.PathLike | None = None) -> tuple[DeepJSCC, Any]:
    """(DeepJSCC module, params) from a model .msgpack (the shipped one when None)."""
    path = Path(path) if path is not None else default_model_path()
    if not path.is_file():
        raise ValueError(f"DeepJSCC model file not found: {path}")
    try:
        state = serialization.msgpack_restore(path.read_bytes())
        model = DeepJSCC(int(state["width"]), bool(state.get("mask_input", False)))
        params = state["params"]
        model.apply({"params": params}, jnp.zeros((1, *IMAGE_SHAPE)), method=DeepJSCC.encode)
    except Exception as e:
        raise ValueError(f"{path}: not a readable DeepJSCC model ({type(e).__name__}: {e})") from e
    if not all(np.isfinite(np.asarray(w)).all() for w in jax.tree_util.tree_leaves(params)):
        raise ValueError(f"{path}: the model's weights are not finite")
    return model, params


def psnr(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Per-image PSNR (dB, peak 1) of ``y`` rounded to 8 bits against ``x``."""
    y = np.round(np.clip(y, 0.0, 1.0) * 255.0) / 255.0
    mse = np.mean((np.asarray(x, np.float64) - y) ** 2, axis=(1, 2, 3))
    return 10.0 * np.log10(1.0 / np.maximum(mse, 1e-10))


def decode_prefixes(model: DeepJSCC, params: Any, x: np.ndarray, ks: Iterable[int]) -> np.ndarray:
    """Decoded images (len(ks), N, 32, 32, 3) of ``x`` from its first k symbols, for each k in ks."""
    s = model.apply({"params": params}, jnp.asarray(x), method=DeepJSCC.encode)

    @jax.jit
    def dec(k: int) -> jax.Array:
        kk = jnp.full((s.shape[0],), k)
        rx = jnp.where(prefix_mask(kk), quantize_iq(truncate(s, kk)), 0.0)
        return model.apply({"params": params}, rx, method=DeepJSCC.decode)

    return np.stack([np.asarray(dec(int(k))) for k in ks])


def compute_curves(model: DeepJSCC, params: Any, x: np.ndarray) -> np.ndarray:
    """C[i, k] in dB for k = 0..M."""
    ys = decode_prefixes(model, params, x, range(M + 1))
    return np.stack([psnr(x, y) for y in ys], axis=1).astype(np.float32)


def write_curves(
    ckpt: str | os.PathLike, out: str | os.PathLike, model_out: str | os.PathLike | None = None
) -> tuple[Path, np.ndarray, dict]:
    """Evaluate the checkpoint in ``ckpt`` and write the curves .npz ``out`` and, when ``model_out``
    is given, the model .msgpack: both paths checked, the weights and the curves validated, before
    anything is written; no other file is touched."""
    out = Path(out)
    if out.suffix != ".npz":
        raise ValueError(f"--out must be a .npz path, got {out}")
    model_out = Path(model_out) if model_out is not None else None
    if model_out is not None and (model_out.suffix != ".msgpack" or model_out.resolve() == out.resolve()):
        raise ValueError(f"--model-out must be a .msgpack path other than --out, got {model_out}")
    for path, what in ((out, "--out"), (model_out, "--model-out")):
        if path is not None:
            if path.is_dir():
                raise ValueError(f"{what} {path} is a folder, not a file")
            check_writable_folder(path.parent, f"the folder of {what}")
    cfg, _ = load_config(ckpt)
    params, _, step, history = load_checkpoint(ckpt, cfg, make_optimizer(cfg))
    if not all(np.isfinite(np.asarray(w)).all() for w in jax.tree_util.tree_leaves(params)):
        raise ValueError(f"{ckpt}: the checkpoint's weights are not finite (training diverged); nothing written")
    model = model_of(cfg)
    blob = model_blob(params, model)
    x, names = data.builtin_test_set()
    C = compute_curves(model, params, x)
    mean = C.mean(axis=0)
    meta = {
        "M": M,
        "image_shape": list(IMAGE_SHAPE),
        "ratio": "1/6",
        "ratio_value": 2 * M / int(np.prod(IMAGE_SHAPE)),
        "bits_per_symbol": BITS_PER_SYMBOL,
        "iq_quantizer": {
            "bits_per_component": BITS_PER_SYMBOL // 2,
            "clip": IQ_CLIP,
            "levels": 2 ** (BITS_PER_SYMBOL // 2),
        },
        "evaluation": "noise-free; first k symbols renormalized to unit average power, 8-bit I/Q, tail zero-padded",
        "psnr": "peak 1.0, decoded image rounded to 8 bits",
        "latent_order": "channel-major (8x8x8 latent, 32 complex symbols per channel)",
        "train_snr_db": cfg.snr_db,
        "train_config": {**cfg.__dict__},
        "train_steps_done": step,
        "train_seconds": history[-1][2] if history else None,
        "dataset": "32x32 crops of colour photos shipped in the scikit-image and scikit-learn wheels"
        + (
            f", {cfg.synthetic_fraction:.0%} of each batch synthetic dead-leaves images"
            if cfg.synthetic_fraction
            else ""
        ),
        "train_photos": list(data.SKIMAGE_TRAIN + data.SKLEARN_TRAIN),
        "train_scales": list(data.SCALES),
        "test_photos": list(data.SKIMAGE_TEST + data.SKLEARN_TEST),
        "test_scales": list(data.TEST_SCALES),
        "num_test_images": len(names),
        "test_images": names,
        "model_file": None if model_out is None else model_out.name,
        "model_hash": hashlib.sha256(blob).hexdigest(),
        "mean_psnr_db": {f: float(mean[k]) for f, k in FRACTIONS.items()},
    }
    validate_curves(C, meta, where=f"the curves of {ckpt}")  # before anything is written
    if model_out is not None:
        atomic_write(model_out, blob)
    save_curves(out, C, meta)
    return out, C, meta


def make_figure(
    out: str | os.PathLike,
    model: str | os.PathLike | None = None,
    curves: str | os.PathLike | None = None,
    n_images: int = 4,
) -> Path:
    """Decoded test images at 0/10/25/50/100 % of the symbols and the mean PSNR-vs-k curve."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    if out.suffix.lower() not in (".png", ".pdf", ".svg") or out.is_dir():
        raise ValueError(f"--out must be a .png, .pdf or .svg file, got {out}")
    check_writable_folder(out.parent, "the folder of --out")
    net, params = load_model(model)
    cv = load_curves(curves)
    x, names = data.builtin_test_set()
    pick = np.linspace(0, len(x) - 1, n_images).round().astype(int)
    fracs = (0.0, 0.1, 0.25, 0.5, 1.0)
    ks = [int(round(f * M)) for f in fracs]
    ys = decode_prefixes(net, params, x[pick], ks)
    fig = plt.figure(figsize=(11, 4.6))
    fig.subplots_adjust(left=0.02, right=0.98)
    cols = len(ks) + 1
    gs = fig.add_gridspec(n_images, cols + 2, width_ratios=[1] * cols + [0.55, 4.2], wspace=0.08, hspace=0.3)
    for r in range(n_images):
        ax = fig.add_subplot(gs[r, 0])
        ax.imshow(x[pick[r]])
        ax.set_axis_off()
        ax.set_title("original" if r == 0 else names[pick[r]].split(":")[0], fontsize=7)
        for c, (f, k) in enumerate(zip(fracs, ks)):
            ax = fig.add_subplot(gs[r, c + 1])
            ax.imshow(np.clip(ys[c, r], 0, 1))
            ax.set_axis_off()
            p = psnr(x[pick[r] : pick[r] + 1], ys[c, r : r + 1])[0]
            ax.set_title(f"{f:.0%} (k={k})\n{p:.1f} dB" if r == 0 else f"{p:.1f} dB", fontsize=7)
    ax = fig.add_subplot(gs[:, cols + 1])
    k = np.arange(cv.M + 1)
    mean, std = cv.C.mean(0), cv.C.std(0)
    ax.fill_between(k, cv.C.min(0), cv.C.max(0), color="C0", alpha=0.12, label="min-max")
    ax.fill_between(k, mean - std, mean + std, color="C0", alpha=0.3, label="±1 std")
    ax.plot(k, mean, color="C0", label=f"mean of {cv.num_images} test crops")
    ax.set_xlabel(f"symbols received k (of M = {cv.M})")
    ax.set_ylabel("PSNR (dB)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title("DeepJSCC, ratio 1/6, 8-bit I/Q, noise-free", fontsize=8)
    return save_figure(fig, out, dpi=90, layout=False, crop=False)
