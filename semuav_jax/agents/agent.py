"""A trained DDQN as one object, the way SB3 users handle a model (docs/ddqn.md, "Agent object"):
``Agent.load(path)`` / ``agent.save(path)`` (config, scenario and weights in one file),
``agent.act(state)`` (the BS's command for one ``EnvState``, through the shield) and
:func:`evaluate` (means with 95 % intervals over test layouts).

    from semuav_jax.agents.agent import Agent, evaluate
    agent = Agent.shipped(seed=0)
    print(evaluate(agent, agent.params.replace(B=25e3), episodes=200))
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import serialization

from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.evaluate import seed_metrics
from semuav_jax.agents.network import QNetwork, q_network
from semuav_jax.agents.policy import agent_input, greedy_policy, initial_state
from semuav_jax.agents.run_config import RunConfig
from semuav_jax.agents.runs import check_weights, load_run, shipped_folder
from semuav_jax.engine import command, numbered
from semuav_jax.io import atomic_write
from semuav_jax.keys import TEST_SEED, episode_keys
from semuav_jax.params import EnvParams
from semuav_jax.stats import mean_ci, wilson_interval

if TYPE_CHECKING:
    from semuav_jax.env import EnvState

FORMAT = "semuav-jax agent 1"


@dataclass(frozen=True)
class Agent:
    """One trained seed: ``run`` is its ``RunConfig`` (config.json of its train.py run), ``weights``
    the Q-network's parameters."""

    run: RunConfig
    weights: Any

    @property
    def config(self) -> DDQNConfig:
        return self.run.agent

    @property
    def params(self) -> EnvParams:
        """The EnvParams the agent was trained with (B: the run's; the agent takes any B in its range)."""
        return self.run.env_params()

    @property
    def network(self) -> QNetwork:
        return q_network(self.params, self.config)

    @classmethod
    def from_run(cls, folder: str | os.PathLike, seed: int = 0) -> Agent:
        """Seed ``seed`` of a finished ``train.py`` run folder."""
        run, nets = load_run(folder)
        if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or not 0 <= seed < run.seeds:
            raise ValueError(f"{folder} has seeds 0..{run.seeds - 1}, got seed={seed}")
        return cls(run, jax.tree.map(lambda w: jnp.asarray(w[seed]), nets))

    @classmethod
    def shipped(cls, seed: int = 0) -> Agent:
        """A seed of the shipped agent (semuav_jax/data/agent, the output of ``python train.py``)."""
        return cls.from_run(shipped_folder(), seed)

    def save(self, path: str | os.PathLike) -> Path:
        """One file: the run description and the weights (msgpack), written atomically."""
        weights = jax.tree.map(np.asarray, self.weights)
        blob = {"format": FORMAT, "run": json.dumps(self.run.to_dict()), "weights": weights}
        return atomic_write(path, serialization.msgpack_serialize(blob))

    @classmethod
    def load(cls, path: str | os.PathLike) -> Agent:
        """The agent saved by :meth:`save`; ValueError (one line) for any other file, and for one
        whose weights do not match its run description's network or are not finite."""
        try:
            blob = serialization.msgpack_restore(Path(path).read_bytes())
            assert isinstance(blob, dict) and blob.get("format") == FORMAT
            run = json.loads(blob["run"])
            assert isinstance(run, dict) and "weights" in blob
        except FileNotFoundError:
            raise
        except Exception:
            raise ValueError(f"{path} is not a semuav-jax agent file (saved by Agent.save)") from None
        run = RunConfig.from_dict(run, path)
        check_weights(run, blob["weights"], path)
        return cls(run, jax.tree.map(jnp.asarray, blob["weights"]))

    def q_values(self, state: EnvState, params: EnvParams | None = None) -> jax.Array:
        """Q-values of every action for one ``EnvState`` (jittable)."""
        params = self.params if params is None else params
        return self.network.apply(self.weights, agent_input(state, params, self.config))

    def numbered(self, state: EnvState, params: EnvParams | None = None) -> EnvState:
        """A new episode's first state with its devices numbered as this agent's BS numbers them
        (along the shortest path for ``config.tour == "shortest"``; else ``state`` itself)."""
        params = self.params if params is None else params
        return numbered(greedy_policy(self.network, self.config), state, params)[0]

    def act(
        self, state: EnvState, params: EnvParams | None = None, policy_state: Any = None
    ) -> tuple[jax.Array, jax.Array, Any]:
        """The BS's command for one ``EnvState``: (action after the shield, acceleration (2,) for
        ``semuav_jax.env.transition``, policy state) (jittable; greedy, epsilon = 0). An option agent
        (eq. 6.4) goes on with the option running in ``policy_state`` (the third item of the last
        call); None starts afresh, as at an episode's start. The action is then the command code.
        An agent whose options follow the shortest path (``config.tour``) expects an episode that
        starts from :meth:`numbered`'s state."""
        params = self.params if params is None else params
        policy = greedy_policy(self.network, self.config)
        ps = initial_state(self.weights, self.config) if policy_state is None else policy_state
        sent, _, accel, ps = command(policy, ps, policy.observe(state, params), state, params)
        return sent, accel, ps


def evaluate(agent: Agent, params: EnvParams | None = None, episodes: int = 1000, seed: int = TEST_SEED) -> dict:
    """The agent's greedy policy on ``episodes`` random layouts (``keys.episode_keys(seed, episodes)``):
    {metric: (mean, 95 % half-width)} for mean_psnr, coverage, shield_share (t intervals) and
    arrived (mean, Wilson interval)."""
    params = agent.params if params is None else params
    if not isinstance(episodes, (int, np.integer)) or isinstance(episodes, bool) or episodes < 2:
        raise ValueError(f"episodes must be an integer >= 2, got {episodes!r}")
    if params.N != agent.params.N:
        raise ValueError(f"the agent was trained with N = {agent.params.N} devices; params has N = {params.N}")
    if not all(np.isfinite(np.asarray(w)).all() for w in jax.tree.leaves(agent.weights)):
        raise ValueError("the agent's weights are not finite (NaN or inf): nothing to evaluate")
    nets = jax.tree.map(lambda w: w[None], agent.weights)
    m = seed_metrics(agent.network, nets, agent.config, episode_keys(seed, episodes), params, (params.B,))
    out = {k: mean_ci(m[k][0, 0]) for k in ("mean_psnr", "coverage", "shield_share")}
    p = float(np.mean(m["arrived"][0, 0]))
    out["arrived"] = (p, tuple(float(x) for x in wilson_interval(p, episodes)))
    return out
