"""Traced runs of the agent and every reference, and the per-episode quantities that explain their
PSNR (Fig. 2's behaviour tables and panel (c), docs/RESULTS.md): speed while transmitting and
otherwise, dwell and symbols per served device, devices covered, mission time.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from baselines import DEFAULT_V_B, init_state, plan_switch, receding, tsp_ranks
from baselines.dwell import DWELL_POLICIES, init_dwell
from baselines.dwell_switch import dwell_switch_metrics
from baselines.planner import PlanState, make_plans, planner
from baselines.policies import POLICIES
from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.network import QNetwork
from semuav_jax.agents.policy import greedy_policy, initial_state
from semuav_jax.params import EnvParams
from semuav_jax.rollout import rollout
from semuav_jax.stats import mean_ci


def behaviour(trace: dict, params: EnvParams) -> dict:
    """Per-episode quantities (E,) of a traced rollout that explain its PSNR: mean speed in the slots
    with some device transmitting and in the others (m/s), dwell (s in range) and symbols (share of M)
    per served device, devices covered, mission time."""
    v = np.linalg.norm(np.asarray(trace["v"]), axis=-1)  # (E, K)
    done = np.asarray(trace["done"])
    live = np.concatenate([np.ones_like(done[:, :1]), ~done[:, :-1]], axis=1)
    x = np.asarray(trace["x"])  # (E, K, N)
    tx = x.any(-1) & live
    idle = ~x.any(-1) & live
    m = np.asarray(trace["m"])[:, -1]  # (E, N) symbols at the end
    served = m > 0
    dwell = (x & live[..., None]).sum(1) * float(params.tau)
    n_served = np.maximum(served.sum(-1), 1)
    return {
        "speed_transmitting": (v * tx).sum(1) / np.maximum(tx.sum(1), 1),
        "speed_otherwise": (v * idle).sum(1) / np.maximum(idle.sum(1), 1),
        "dwell_per_served_s": (dwell * served).sum(-1) / n_served,
        "symbols_per_served": (m / params.M * served).sum(-1) / n_served,
        "coverage": served.sum(-1).astype(float),
        "mission_time_s": live.sum(1) * float(params.tau),
    }


def summarize(per_episode: dict) -> dict:
    """Mean and t half-width (95 %) of every per-episode quantity."""
    return {k: mean_ci(v) for k, v in per_episode.items()}


def traced_runs(
    network: QNetwork,
    nets: Any,
    config: DDQNConfig,
    keys: jax.Array,
    params: EnvParams,
    tuned_speeds: dict,
    workers: int = 2,
    rank: np.ndarray | None = None,
    plan: PlanState | None = None,
) -> dict[str, tuple[dict[str, np.ndarray], dict[str, np.ndarray]]]:
    """Traced rollouts at ``params.B``: each agent seed, greedy and TSP at 8.9 m/s and at v_b*
    (``tuned_speeds``: name -> v_b*, the dwell rules' name -> (v_c, k*, margin) and, optionally,
    "dwell-switch" -> (v_c, margin)), the dwell rules, dwell-switch, the planner, the exact
    planner and (with dwell-switch's knobs) plan-switch. ``rank`` (TSP ranks of ``keys``) and
    ``plan`` (the planner's PlanState at ``params.B``) are solved here unless given.
    Returns {name: (metrics, trace)}."""
    runs = {}
    for s in range(jax.tree.leaves(nets)[0].shape[0]):
        net = jax.tree.map(lambda x, s=s: x[s], nets)
        runs[f"agent seed {s}"] = rollout(
            greedy_policy(network, config), keys, params, initial_state(net, config), trace=True, state_axes=None
        )
    ranks = {
        "greedy": np.broadcast_to(np.arange(params.N, dtype=np.int32), (len(keys), params.N)),
        "tsp": tsp_ranks(keys, params, workers=workers) if rank is None else rank,
    }
    for name in ("greedy", "tsp"):
        for label, v in ((f"{name} {DEFAULT_V_B:g}", DEFAULT_V_B), (f"{name} v_b*", tuned_speeds[name])):
            states = jax.vmap(init_state, (None, 0))(jnp.float32(v), jnp.asarray(ranks[name]))
            runs[label] = rollout(POLICIES[name], keys, params, states, trace=True)
    for name, policy in ((n, f) for n, f in DWELL_POLICIES.items() if n in tuned_speeds):
        states = jax.vmap(init_dwell, (None, None, None, 0))(*tuned_speeds[name], jnp.asarray(ranks["tsp"]))
        runs[name] = rollout(policy, keys, params, states, trace=True)
    if "dwell-switch" in tuned_speeds:
        m, _, tr = dwell_switch_metrics(keys, params, *tuned_speeds["dwell-switch"], ranks["tsp"], trace=True)
        runs["dwell-switch"] = (m, tr)
    plan = make_plans(keys, params, workers=workers) if plan is None else plan
    runs["planner"] = rollout(planner, keys, params, plan, trace=True)
    runs["exact planner"] = receding.fly(keys, params, workers=workers, trace=True)
    if "dwell-switch" in tuned_speeds:
        m, _, tr = plan_switch.fly(
            keys, params, *tuned_speeds["dwell-switch"], ranks["tsp"], workers=workers, trace=True
        )
        runs["plan-switch"] = (m, tr)
    return {k: jax.tree.map(np.asarray, v) for k, v in runs.items()}


def path(trace: dict, metrics: dict, i: int, params: EnvParams) -> dict:
    """Episode i of a traced run as drawn in panel (c): positions (slots + 1, 2) from q0, speeds,
    seconds in range of each device, and the final metrics."""
    slots = int(round(float(metrics["mission_time"][i]) / float(params.tau)))
    q = np.concatenate([np.asarray(params.q0)[None], trace["q"][i, :slots]])
    v = np.concatenate([[0.0], np.linalg.norm(trace["v"][i, :slots], axis=-1)])
    dwell = trace["x"][i, :slots].sum(0) * float(params.tau)
    return {"q": q, "speed": v, "dwell_s": dwell, **{k: float(np.asarray(m)[i]) for k, m in metrics.items()}}
