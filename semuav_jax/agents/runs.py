"""Run folders, the one format for a trained agent (docs/ddqn.md, "Run folder"): ``config.json``
(the run's ``RunConfig``: env, agent, seeds, the command), ``model.msgpack`` (the
weights of every seed, leading seed axis), ``checkpoint.msgpack`` (the whole training state while
it runs), ``metrics.csv`` (per-chunk training metrics), ``eval.json`` / ``eval.md`` (the comparison
with the references). ``train.py`` writes them; ``eval.py`` and the shipped agent read them."""

from __future__ import annotations

import json
import os
from importlib import resources
from pathlib import Path
from typing import Any

from flax import serialization

from semuav_jax.agents.run_config import RunConfig

CONFIG_FILE, METRICS_FILE, CKPT_FILE, MODEL_FILE = "config.json", "metrics.csv", "checkpoint.msgpack", "model.msgpack"
EVAL_FILE, EVAL_MD = "eval.json", "eval.md"
CURVE_FILE = "learning_curve.png"
RUN_FILES = (CONFIG_FILE, METRICS_FILE, CKPT_FILE, MODEL_FILE, EVAL_FILE, EVAL_MD, CURVE_FILE)  # all a run writes
SHIPPED = "agent"  # the shipped run folder, semuav_jax/data/agent: the output of ``python train.py``


def finished(folder: str | os.PathLike) -> bool:
    folder = Path(folder)
    return (folder / CONFIG_FILE).is_file() and (folder / MODEL_FILE).is_file()


def check_weights(run: RunConfig, weights: Any, where: str | os.PathLike, seeds: int | None = None) -> None:
    """ValueError (one line) unless ``weights`` are finite arrays with the shapes of the Q-network
    of ``run``, with a leading axis of ``seeds`` when given."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from semuav_jax.agents.network import q_network
    from semuav_jax.agents.policy import input_size

    try:
        params = run.env_params()
    except (ValueError, FileNotFoundError) as e:
        raise ValueError(f"{where}: its run config does not build its env ({e})") from None
    net = q_network(params, run.agent)
    want = jax.eval_shape(net.init, jax.random.key(0), jnp.zeros((input_size(params, run.agent),), jnp.float32))
    lead = () if seeds is None else (seeds,)
    shapes = lambda tree: {
        "/".join(str(getattr(k, "key", k)) for k in path): np.shape(x)
        for path, x in jax.tree_util.tree_flatten_with_path(tree)[0]
    }
    got, want = shapes(weights), {k: lead + v for k, v in shapes(want).items()}
    if got != want:
        bad = [f"{k} {got.get(k, 'missing')} (expected {want[k]})" for k in want if got.get(k) != want[k]]
        bad += [f"{k} (not a layer of it)" for k in got if k not in want]
        raise ValueError(
            f"{where}: its weights do not match its config (hidden {list(run.agent.hidden)}, "
            f"{net.num_actions} actions): {', '.join(bad[:3])}"
        )
    if not all(np.issubdtype(np.asarray(w).dtype, np.floating) for w in jax.tree.leaves(weights)):
        raise ValueError(f"{where}: its weights are not float arrays")
    if not all(np.isfinite(np.asarray(w)).all() for w in jax.tree.leaves(weights)):
        raise ValueError(f"{where}: its weights are not finite (NaN or inf: the training diverged)")


def read_config(path: str | os.PathLike) -> RunConfig:
    """The ``RunConfig`` of a config.json; ValueError (one line) for a file that is not one."""
    try:
        d = json.loads(Path(path).read_text())
    except ValueError as e:
        raise ValueError(f"{path} is not a train.py run config ({e})") from None
    return RunConfig.from_dict(d, path)


def load_run(folder: str | os.PathLike) -> tuple[RunConfig, dict]:
    """(run config, weights with a leading seed axis) of a finished run folder, its weights checked
    against its config and finite."""
    folder = Path(folder)
    if not finished(folder):
        raise ValueError(f"{folder} is not a finished train.py run (needs {CONFIG_FILE} and {MODEL_FILE})")
    run = read_config(folder / CONFIG_FILE)
    try:
        nets = serialization.msgpack_restore((folder / MODEL_FILE).read_bytes())
    except Exception as e:  # noqa: BLE001 - msgpack raises any kind for a file that is not one
        raise ValueError(f"{folder / MODEL_FILE} is not a weights file ({type(e).__name__})") from None
    check_weights(run, nets, folder / MODEL_FILE, run.seeds)
    return run, nets


def shipped_folder() -> Path:
    return Path(str(resources.files("semuav_jax") / "data" / SHIPPED))
