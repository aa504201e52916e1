"""The shipped DDQN agent: random layouts, gain reward, B = 20 kHz, gamma 0.999, return-home
shield, 3 M steps on session 2's DeepJSCC curves (``ddqn_random.json`` says how; docs/ddqn.md).
``eval.py --quick`` fine-tunes it per bandwidth instead of training from scratch."""

from __future__ import annotations

import json
from importlib import resources

import jax
from flax import serialization

from semuav_jax.agents.ddqn import DDQNConfig

MODEL, CONFIG = "ddqn_random.msgpack", "ddqn_random.json"


def seed0_weights(model_bytes: bytes):
    """The first seed's network weights from a ``train.py`` ``model.msgpack`` (a leading seed axis)."""
    return jax.tree.map(lambda x: x[0], serialization.msgpack_restore(model_bytes))


def load_pretrained():
    """(config, run description, network weights) of the shipped agent."""
    data = resources.files("semuav_jax") / "data"
    run = json.loads((data / CONFIG).read_text())
    return DDQNConfig.from_dict(run["ddqn"]), run, seed0_weights((data / MODEL).read_bytes())
