"""Run folders, the one format for a trained agent (docs/ddqn.md, "Run folder"): ``config.json``
(how it was trained: scenario, seeds, the command, the DDQNConfig), ``model.msgpack`` (the
weights of every seed, leading seed axis), ``checkpoint.msgpack`` (the whole training state while
it runs), ``metrics.csv`` (per-chunk training metrics), ``eval.json`` / ``eval.md`` (the comparison
with the references). ``train.py`` writes them; ``eval.py`` and the shipped agent read them."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

from flax import serialization

from semuav_jax.agents.ddqn import DDQNConfig

CONFIG_FILE, METRICS_FILE, CKPT_FILE, MODEL_FILE = "config.json", "metrics.csv", "checkpoint.msgpack", "model.msgpack"
EVAL_FILE, EVAL_MD = "eval.json", "eval.md"
SHIPPED = "agent"  # the shipped run folder, semuav_jax/data/agent: the output of ``python train.py``


def finished(folder) -> bool:
    folder = Path(folder)
    return (folder / CONFIG_FILE).is_file() and (folder / MODEL_FILE).is_file()


def load_run(folder):
    """(run description, DDQNConfig, weights with a leading seed axis) of a finished run folder."""
    folder = Path(folder)
    if not finished(folder):
        raise ValueError(f"{folder} is not a finished train.py run (needs {CONFIG_FILE} and {MODEL_FILE})")
    run = json.loads((folder / CONFIG_FILE).read_text())
    if "ddqn" not in run:
        raise ValueError(f"{folder / CONFIG_FILE} has no 'ddqn' block")
    return run, DDQNConfig.from_dict(run["ddqn"]), serialization.msgpack_restore((folder / MODEL_FILE).read_bytes())


def shipped_folder() -> Path:
    return Path(str(resources.files("semuav_jax") / "data" / SHIPPED))


def load_shipped():
    """The shipped agent: :func:`load_run` of ``semuav_jax/data/agent``."""
    return load_run(shipped_folder())
