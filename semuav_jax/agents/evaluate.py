"""Greedy (epsilon = 0) evaluation of a trained DDQN and paired comparison with the baselines.

Episodes run through the baselines' shared evaluation path (``baselines.run``: one jitted,
vmapped ``semuav_jax.rollout`` program, MODEL.md section 8 metrics), on the same per-episode keys.
"""

from __future__ import annotations

import functools

import jax
import numpy as np

from baselines import DEFAULT_V_B
from baselines import evaluate as baseline_evaluate
from baselines import run as baseline_run
from semuav_jax.actions import action_to_accel
from semuav_jax.agents.shield import shield
from semuav_jax.observation import observation
from semuav_jax.params import EnvParams, validate_params
from semuav_jax.stats import mean_ci


@functools.lru_cache(maxsize=None)
def greedy_policy(network, shield_margin: float | None = None):
    """Rollout policy ``(net_params, env_state, params) -> (accel, net_params)``: argmax Q of the
    observation, through the return-home shield unless ``shield_margin`` is None."""

    def policy(net_params, state, params: EnvParams):
        a = jax.numpy.argmax(network.apply(net_params, observation(state, params)))
        return action_to_accel(shield(a, state, params, shield_margin), params), net_params

    return policy


def evaluate_agent(network, net_params, keys, params: EnvParams, shield_margin: float | None = None) -> dict:
    """Metrics (dict of (E,) NumPy arrays) of the greedy policy of ``net_params`` on episodes ``keys``."""
    validate_params(params)
    policy = greedy_policy(network, shield_margin)
    return jax.tree.map(np.asarray, baseline_run(policy, keys, params, net_params, state_axes=None))


def baseline_results(keys, params: EnvParams, baselines=("greedy", "tsp"), v_b=None) -> dict:
    """Per-episode metrics of each baseline on episodes ``keys``."""
    v_b = DEFAULT_V_B if v_b is None else v_b
    return {b: baseline_evaluate(b, keys, params, v_b=v_b) for b in baselines}


def compare(
    network, net_params, keys, params: EnvParams, reference: dict | None = None, shield_margin: float | None = None
) -> dict:
    """Mean PSNR of the agent and of each baseline on the same episodes, with paired margins.

    ``reference`` is :func:`baseline_results` on the same ``keys`` (computed here when None).
    Returns ``{name: {metric: (mean, ci95)}, "margin_vs_<b>": (mean, ci95)}``; the margin is the
    per-episode difference agent - baseline (same layout, delays and images).
    """
    reference = baseline_results(keys, params) if reference is None else reference
    agent = evaluate_agent(network, net_params, keys, params, shield_margin)
    out = {}
    for name, m in {"ddqn": agent, **reference}.items():
        out[name] = {k: mean_ci(m[k]) for k in ("mean_psnr", "coverage", "arrived", "mission_time")}
    for name, m in reference.items():
        out[f"margin_vs_{name}"] = mean_ci(agent["mean_psnr"] - m["mean_psnr"])
    return out
