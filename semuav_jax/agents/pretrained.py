"""The shipped DDQN agent: random layouts, gain reward, B = 20 kHz, trained by ``python train.py
--scenario random`` on the shipped DeepJSCC curves (docs/ddqn.md). ``eval.py --quick`` fine-tunes
it per bandwidth instead of training from scratch."""

from __future__ import annotations

import json
from importlib import resources

import jax
from flax import serialization

from semuav_jax.agents.ddqn import DDQNConfig

MODEL, CONFIG = "ddqn_random.msgpack", "ddqn_random.json"


def load_pretrained():
    """(config, run description, network weights) of the shipped agent."""
    data = resources.files("semuav_jax") / "data"
    run = json.loads((data / CONFIG).read_text())
    weights = serialization.msgpack_restore((data / MODEL).read_bytes())
    return DDQNConfig.from_dict(run["ddqn"]), run, jax.tree.map(lambda x: x[0], weights)
