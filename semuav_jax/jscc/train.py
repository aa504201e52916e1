"""Training of the DeepJSCC with random prefix truncation (MODEL.md section 9).

Each example keeps a prefix of k symbols, renormalized to unit power and sent over AWGN at
``snr_db``; the tail is zero-padded at the decoder. k is uniform in {0, ..., M} for 3/4 of the
examples and in {0, ..., M/2} for the rest (biased toward short prefixes, for graceful
degradation). The loss is the mean over examples of 10 log10(MSE + 1e-4), i.e. minus the
PSNR (capped at 40 dB), so that the short prefixes, whose errors are an order of magnitude
larger, do not dominate the gradient as they do with a plain MSE. The batch of step t is
drawn from ``numpy.random.default_rng([seed, t])`` and the channel key from
``fold_in(PRNGKey(seed), t)``, so a resumed run is identical to an uninterrupted one.

Monotone training (``monotone_weight > 0``; the defaults are the shipped model's recipe,
docs/deepjscc.md): every crop is decoded from two prefixes k1 < k2 of the same transmission
with the same channel noise on the shared symbols (k2 = M for a quarter of the crops, uniform in
{1, ..., M} otherwise; k1 = max(k2 - d, 0) with d uniform in {1, ..., ``monotone_gap``} for half
of the crops, uniform in {0, ..., k2 - 1} otherwise). The loss is the log-MSE at both prefixes
plus ``monotone_weight`` times the mean hinge relu(loss(k2) - loss(k1) + ``monotone_margin``),
which trains the decoder to do at least as well from a longer prefix as from a shorter one. It
runs from the first step, or as a fine-tune of a finished run named by ``init_from`` (whose
parameters start the run; the optimizer starts afresh). ``monotone_weight = 0`` is the plain
loss above (the mean PSNR-vs-k curve of such a model sags beyond k ~ 160).

``synthetic_fraction`` (default 0.25) is the share of every batch made of dead-leaves images
(``data.dead_leaves``); ``mask_input`` (off by default and in the shipped model) lets the decoder
see which latent entries arrived.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import numpy as np
import optax

from semuav_jax import checkpoint
from semuav_jax.io import atomic_write
from semuav_jax.jscc.config import TrainConfig
from semuav_jax.jscc.data import sample_batch
from semuav_jax.jscc.loss import make_optimizer, make_train_step, model_of, transmit  # noqa: F401 - transmit: re-exported
from semuav_jax.jscc.model import IMAGE_SHAPE, M

if TYPE_CHECKING:
    from semuav_jax.runfolder import RunFolder

CKPT_FILE = "checkpoint.msgpack"
CONFIG_FILE = "config.json"


def init_params(cfg: TrainConfig) -> Any:
    model = model_of(cfg)
    x = jnp.zeros((1, *IMAGE_SHAPE), jnp.float32)
    return model.init(jax.random.PRNGKey(cfg.seed), x, jnp.array([M]), jax.random.PRNGKey(0), cfg.snr_db)["params"]


def start_params(cfg: TrainConfig) -> Any:
    """Parameters a fresh run starts from: random, or those of the run in ``cfg.init_from``."""
    if cfg.init_from is None:
        return init_params(cfg)
    src_cfg, _ = load_config(cfg.init_from)
    for name in ("width", "mask_input"):
        if getattr(src_cfg, name) != getattr(cfg, name):
            raise ValueError(
                f"--init-from {cfg.init_from} has {name} {getattr(src_cfg, name)}, not {getattr(cfg, name)}"
            )
    params, _, _, _ = load_checkpoint(cfg.init_from, src_cfg, make_optimizer(src_cfg))
    return params


def _config_text(cfg: TrainConfig) -> str:
    return json.dumps({"config": dataclasses.asdict(cfg)}, indent=1)


def save_checkpoint(
    out: Path, cfg: TrainConfig, params: Any, opt_state: optax.OptState, step: int, history: list
) -> None:
    """Write the run's state (parameters, optimizer, step and history) as one checkpoint file,
    atomically; config.json, which holds only the config, is written before it when it does not hold
    this config yet. A kill at any moment leaves either the previous checkpoint or this one, each
    with its own step and history, beside the right config."""
    p = out / CONFIG_FILE
    try:
        current = json.loads(p.read_text()).get("config") if p.is_file() else None
    except (ValueError, AttributeError):
        current = None
    if current != json.loads(json.dumps(dataclasses.asdict(cfg))):
        atomic_write(p, _config_text(cfg).encode())
    state = {
        "params": params,
        "opt_state": opt_state,
        "step": step,
        "history": np.asarray(history, np.float64).reshape(-1, 3),
    }
    checkpoint.save(out / CKPT_FILE, state)


def check_out(out: str | os.PathLike, resume: bool = False, overwrite: bool = False) -> RunFolder:
    """The directory ``out`` claimed for checkpoints (``semuav_jax.runfolder``: ours or new, locked);
    ValueError unless it can be written and, unless ``resume`` or ``overwrite``, holds none yet."""
    from semuav_jax.runfolder import RunFolder

    out = Path(out)
    if resume and overwrite:
        raise ValueError("give at most one of --resume and --overwrite")
    folder = RunFolder.claim(out, "jscc train", adopt=() if overwrite else (CKPT_FILE, CONFIG_FILE))
    held = [n for n in (CKPT_FILE, CONFIG_FILE) if (out / n).exists()]
    if held and not (resume or overwrite):
        folder.release()
        raise ValueError(
            f"--out {out} already holds a checkpoint ({', '.join(held)}): "
            "give --resume to continue it or --overwrite to replace it"
        )
    for n in (CKPT_FILE, CONFIG_FILE):
        folder.record(n)
    return folder


def load_config(ckpt_dir: str | os.PathLike) -> tuple[TrainConfig, dict]:
    """(config, contents of config.json) of a checkpoint directory; ValueError if absent or broken.
    The step and history are in the checkpoint itself (:func:`load_checkpoint`)."""
    p = Path(ckpt_dir) / CONFIG_FILE
    if not p.is_file():
        raise ValueError(f"{ckpt_dir} is not a DeepJSCC checkpoint directory (no {CONFIG_FILE})")
    try:
        meta = json.loads(p.read_text())
        return TrainConfig(**meta["config"]), meta
    except Exception as e:
        raise ValueError(f"{p}: unreadable checkpoint config ({type(e).__name__}: {e})") from e


def load_checkpoint(
    ckpt_dir: str | os.PathLike, cfg: TrainConfig, opt: optax.GradientTransformation
) -> tuple[Any, optax.OptState, int, list]:
    """(params, opt_state, step, history) restored from ``ckpt_dir``; ValueError (one line) if the
    checkpoint is unreadable or its arrays are not those of ``cfg``. ``history`` is the list of
    (step, mean loss, elapsed seconds) of the checkpoint (of config.json for checkpoints written
    before it held one)."""
    params = init_params(cfg)
    template = {"params": params, "opt_state": opt.init(params), "step": 0}
    state, extras = checkpoint.restore(Path(ckpt_dir) / CKPT_FILE, template, free=("history",))
    history = extras["history"]
    if history is None:  # written before checkpoints held their history
        history = load_config(ckpt_dir)[1].get("history", [])
    history = [(int(s), float(loss), float(t)) for s, loss, t in np.asarray(history, np.float64).reshape(-1, 3)]
    return state["params"], state["opt_state"], int(state["step"]), history


def train(
    cfg: TrainConfig,
    photos: list[np.ndarray],
    out: str | os.PathLike | None = None,
    resume: bool = False,
    minutes: float | None = None,
    overwrite: bool = False,
    ckpt_every_s: float = 60.0,
    progress: bool = True,
    log_every: int = 100,
) -> tuple[Any, list]:
    """Train (or resume) up to ``cfg.steps`` steps or ``minutes`` wall-clock; returns (params, history).

    ``history`` holds (step, mean loss over the last ``log_every`` steps, elapsed seconds); the
    wall-clock limit and checkpoints are checked every ``log_every`` steps. A fresh run refuses an
    ``out`` that holds a checkpoint unless ``overwrite``, which deletes the checkpoint (and nothing
    else) once the starting parameters are built; temporary files of a killed save are removed.
    """
    cfg.validate()
    if not photos:
        raise ValueError("no training photos")
    out = Path(out) if out is not None else None
    folder = check_out(out, resume, overwrite) if out is not None else None  # removes a killed save's temporaries
    try:
        return _train(cfg, photos, out, resume, minutes, overwrite, ckpt_every_s, progress, log_every)
    finally:
        if folder is not None:
            folder.release()


def _train(
    cfg: TrainConfig,
    photos: list[np.ndarray],
    out: str | os.PathLike | None,
    resume: bool,
    minutes: float | None,
    overwrite: bool,
    ckpt_every_s: float,
    progress: bool,
    log_every: int,
) -> tuple[Any, list]:
    opt = make_optimizer(cfg)
    history: list = []
    start, elapsed0 = 0, 0.0
    if resume:
        if out is None:
            raise ValueError("--resume needs --out pointing at an existing checkpoint directory")
        saved_cfg, _ = load_config(out)
        if saved_cfg != cfg:
            raise ValueError(f"--resume with a different config: saved {saved_cfg}, given {cfg}")
    if resume and (out / CKPT_FILE).exists():
        params, opt_state, start, history = load_checkpoint(out, cfg, opt)
        elapsed0 = history[-1][2] if history else 0.0
    else:  # a fresh run, or one killed after writing its config.json and before its first checkpoint
        params = start_params(cfg)
        opt_state = opt.init(params)
        if overwrite and out is not None:
            for n in (CKPT_FILE, CONFIG_FILE):
                (out / n).unlink(missing_ok=True)
    step_fn = make_train_step(cfg)
    base_key = jax.random.PRNGKey(cfg.seed)
    t0, last_ckpt = time.time(), time.time()
    window = []
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=cfg.steps, initial=start, desc="train", unit="step", mininterval=5.0)
    step = start
    while step < cfg.steps:
        x = sample_batch(photos, cfg.batch, np.random.default_rng([cfg.seed, step]), cfg.synthetic_fraction)
        params, opt_state, loss = step_fn(params, opt_state, x, jax.random.fold_in(base_key, step))
        window.append(loss)
        step += 1
        if bar is not None:
            bar.update(1)
        if step % log_every == 0 or step == cfg.steps:
            mean_loss = float(np.mean(np.asarray(jax.device_get(window))))
            window = []
            if not (np.isfinite(mean_loss) and all(np.isfinite(w).all() for w in jax.tree_util.tree_leaves(params))):
                kept = f"; {out} keeps its last checkpoint" if out is not None and (out / CKPT_FILE).is_file() else ""
                raise ValueError(
                    f"training diverged at step {step} (loss {mean_loss}, or non-finite weights): nothing "
                    f"saved for it{kept}; change the options (e.g. --lr, --snr-db) and start again"
                )
            history.append((step, mean_loss, elapsed0 + time.time() - t0))
            if bar is not None:
                bar.set_postfix(psnr=f"{-mean_loss:.2f}")
            timed_out = minutes is not None and time.time() - t0 > 60.0 * minutes
            if out is not None and (step == cfg.steps or timed_out or time.time() - last_ckpt > ckpt_every_s):
                save_checkpoint(out, cfg, params, opt_state, step, history)
                last_ckpt = time.time()
            if timed_out:
                break
    if bar is not None:
        bar.close()
    return params, history
