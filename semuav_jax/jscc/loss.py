"""The loss and update step of the DeepJSCC's training (MODEL.md section 9; the recipe is described
in ``semuav_jax.jscc.train``): the channel a training example goes through, the log-MSE loss (with
the monotone hinge), the optimizer."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import optax

from semuav_jax.jscc.model import (
    DeepJSCC,
    M,
    complex_noise,
    prefix_mask,
    quantize_iq,
    truncate,
)

if TYPE_CHECKING:
    from semuav_jax.jscc.config import TrainConfig

MSE_FLOOR = 1e-4


def make_optimizer(cfg: TrainConfig) -> optax.GradientTransformation:
    warmup = min(200, cfg.steps // 10)
    sched = optax.warmup_cosine_decay_schedule(0.0, cfg.lr, warmup, cfg.steps, end_value=cfg.lr * 0.02)
    return optax.chain(optax.clip_by_global_norm(1.0), optax.adam(sched))


def model_of(cfg: TrainConfig) -> DeepJSCC:
    """The network a config trains."""
    return DeepJSCC(cfg.width, cfg.mask_input)


def transmit(cfg: TrainConfig, s: jax.Array, k: jax.Array, key: jax.Array, copies: int = 1) -> jax.Array:
    """Received symbols of ``copies`` stacked transmissions of ``s`` (B, M), copy j keeping the
    first ``k[j*B + b]`` symbols, renormalized, through ``cfg.channel`` (AWGN at ``snr_db``, the
    same noise in every copy; or the noise-free 8-bit I/Q quantizer of the curves, with a
    straight-through gradient); the tail is zero-padded."""
    mask = prefix_mask(k, s.shape[-1])
    tx = truncate(jnp.tile(s, (copies, 1)), k)
    if cfg.channel == "awgn":
        rx = tx + jnp.tile(complex_noise(key, s.shape, cfg.snr_db), (copies, 1))
    else:
        rx = tx + jax.lax.stop_gradient(quantize_iq(tx) - tx)
    return jnp.where(mask, rx, 0.0)


def _log_mse(y: jax.Array, x: jax.Array) -> jax.Array:
    return 10.0 * jnp.log10(jnp.mean((y - x) ** 2, axis=(1, 2, 3)) + MSE_FLOOR)


@functools.lru_cache(maxsize=4)
def make_train_step(cfg: TrainConfig) -> Callable[[Any, Any, jax.Array, jax.Array], tuple[Any, Any, jax.Array]]:
    """Jitted (params, opt_state, x, key) -> (params, opt_state, loss); cached per config."""
    model = model_of(cfg)
    opt = make_optimizer(cfg)

    def loss_fn(params: Any, x: jax.Array, k: jax.Array, key: jax.Array) -> jax.Array:
        s = model.apply({"params": params}, x, method=DeepJSCC.encode)
        y = model.apply({"params": params}, transmit(cfg, s, k, key), method=DeepJSCC.decode)
        return jnp.mean(_log_mse(y, x))

    def plain_draw(key: jax.Array, b: int) -> tuple[jax.Array]:
        k_max = jnp.where(jax.random.bernoulli(key, 0.75, (b,)), M, M // 2)
        return (jax.random.randint(jax.random.fold_in(key, 1), (b,), 0, k_max + 1),)

    def mono_loss_fn(params: Any, x: jax.Array, k1: jax.Array, k2: jax.Array, key: jax.Array) -> jax.Array:
        s = model.apply({"params": params}, x, method=DeepJSCC.encode)
        k = jnp.concatenate([k1, k2])
        rx = transmit(cfg, s, k, key, copies=2)
        y = model.apply({"params": params}, rx, method=DeepJSCC.decode)
        l1, l2 = jnp.split(_log_mse(y, jnp.concatenate([x, x])), 2)
        hinge = jax.nn.relu(l2 - l1 + cfg.monotone_margin)
        return 0.5 * jnp.mean(l1 + l2) + cfg.monotone_weight * jnp.mean(hinge)

    def mono_draw(key: jax.Array, b: int) -> tuple[jax.Array, jax.Array]:
        c = jax.random.split(key, 5)
        k2 = jnp.where(jax.random.bernoulli(c[0], 0.25, (b,)), M, jax.random.randint(c[1], (b,), 1, M + 1))
        near = jnp.maximum(k2 - jax.random.randint(c[2], (b,), 1, cfg.monotone_gap + 1), 0)
        far = jax.random.randint(c[3], (b,), 0, k2)
        return jnp.where(jax.random.bernoulli(c[4], 0.5, (b,)), near, far), k2

    mono = cfg.monotone_weight > 0
    loss_of, draw = (mono_loss_fn, mono_draw) if mono else (loss_fn, plain_draw)

    @jax.jit
    def step(
        params: Any, opt_state: optax.OptState, x: jax.Array, key: jax.Array
    ) -> tuple[Any, optax.OptState, jax.Array]:
        kk, kn = jax.random.split(key)
        loss, grads = jax.value_and_grad(loss_of)(params, x, *draw(kk, x.shape[0]), kn)
        updates, opt_state = opt.update(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, loss

    return step
