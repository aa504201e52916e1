"""The paper's Fig. 2 as sweeps over traced parameters (docs/RESULTS.md).

(a) mean PSNR vs the devices' bandwidth B (baselines at 8.9 m/s), (b) mean PSNR vs the baselines'
speed at B = 25 kHz, (c) the trajectories of the three policies on the paper layout.
The DDQN points of (a) come from one agent per bandwidth, trained together by ``jax.vmap`` over
B; every point of every policy is evaluated on the same random layouts, delays and images.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

import baselines
from semuav_jax.agents.ddqn import DDQNConfig, make_train
from semuav_jax.agents.evaluate import agent_state, greedy_policy
from semuav_jax.stats import mean_ci
from semuav_jax.params import EnvParams
from semuav_jax.rollout import rollout
from semuav_jax.sharding import shard_episodes

BANDWIDTHS = (5e3, 10e3, 15e3, 20e3, 25e3, 30e3, 35e3, 40e3)
VELOCITIES = (4.0, 6.0, baselines.DEFAULT_V_B, 11.0, 14.0, 17.0, 20.0, 24.0)
PANEL_B_BANDWIDTH = 25e3
# eval.py --quick: fewer points, and the shipped agent fine-tuned per bandwidth (low exploration)
QUICK = {"bandwidths": (5e3, 20e3, 25e3, 40e3), "velocities": (4.0, 8.9, 16.0, 24.0), "total_steps": 320_000,
         "eps_start": 0.1}
SUMMARY = ("mean_psnr", "coverage", "arrived", "psnr_visited", "mission_time")


@dataclasses.dataclass
class BandwidthAgents:
    """DDQN agents trained at each bandwidth: ``net_params`` has a leading axis over ``bandwidths``."""

    network: object
    net_params: object
    bandwidths: tuple
    curves: dict  # per-chunk training metrics, (len(bandwidths), chunks) arrays
    config: DDQNConfig  # how they were trained: action mode, input, shield


def train_over_bandwidth(
    config: DDQNConfig, params: EnvParams, bandwidths, key, segments=4, progress=None, init_weights=None
):
    """Train one agent per bandwidth in one vmapped program (own key each), in ``segments`` host steps.

    ``init_weights`` (one network's weights) starts every agent from them instead of a random
    initialization (fine-tuning). ``progress(chunks_done)`` is called after each segment.
    """
    n_agents = len(bandwidths)
    keys, B = shard_episodes((jax.random.split(key, n_agents), jnp.asarray(bandwidths, jnp.float32)))
    trainer_at = lambda b: make_train(config, params.replace(B=b))
    state = jax.jit(jax.vmap(lambda k, b: trainer_at(b).init(k)))(keys, B)
    if init_weights is not None:
        w = jax.tree.map(lambda x: jnp.broadcast_to(x, (len(keys),) + x.shape), init_weights)
        state = state.replace(params=w, target_params=w)
    seg = -(-config.num_chunks // segments)
    runs, history, done = {}, [], 0
    while done < config.num_chunks:
        n = min(seg, config.num_chunks - done)
        if n not in runs:
            runs[n] = jax.jit(jax.vmap(lambda s, b, n=n: trainer_at(b).run(s, n)))
        state, metrics = runs[n](state, B)
        history.append(jax.tree.map(np.asarray, metrics))
        done += n
        if progress is not None:
            progress(n)
    curves = {k: np.concatenate([h[k] for h in history], axis=1)[:n_agents] for k in history[0]}
    net_params = jax.tree.map(lambda x: x[:n_agents], state.params)
    network = make_train(config, params).network
    return BandwidthAgents(network, net_params, tuple(bandwidths), curves, config)


def ddqn_sweep(agents: BandwidthAgents, keys, params: EnvParams) -> dict:
    """Metrics (len(bandwidths), E) of each agent's greedy policy at its own bandwidth."""
    policy = greedy_policy(agents.network, agents.config)
    E = len(keys)
    skeys = shard_episodes(keys)

    def at(net, b):
        return rollout(policy, skeys, params.replace(B=b), policy_state=agent_state(net), state_axes=None)[0]

    out = jax.jit(jax.vmap(at))(agents.net_params, jnp.asarray(agents.bandwidths, jnp.float32))
    return {k: np.asarray(v)[:, :E] for k, v in out.items()}


def baseline_sweep(policy: str, keys, params: EnvParams, bandwidths, velocities, **tsp_kwargs) -> dict:
    """Metrics (len(bandwidths), len(velocities), E) of a baseline over the B x v_b grid, one program."""
    E = len(keys)
    rank = baselines.tsp_ranks(keys, params, **tsp_kwargs) if policy == "tsp" else None
    skeys = shard_episodes(keys)
    srank = None if rank is None else shard_episodes(rank)
    out = baselines.sweep(policy, skeys, params, v_b=velocities, B=bandwidths, rank=srank)
    return {k: v[..., :E] for k, v in out.items()}


def trajectories(agents: BandwidthAgents, agent_index: int, params: EnvParams, key) -> dict:
    """Positions (slots + 1, 2) and final metrics of DDQN, greedy and TSP on the episode of ``key``."""
    keys = key[None]
    net = jax.tree.map(lambda x: x[agent_index], agents.net_params)
    runs = {"DDQN": rollout(greedy_policy(agents.network, agents.config), keys, params, policy_state=agent_state(net),
                            state_axes=None, trace=True)}
    for name in ("greedy", "tsp"):
        rank = baselines.tsp_ranks(keys, params) if name == "tsp" else np.arange(params.N)[None]
        state = jax.vmap(baselines.init_state, (None, 0))(jnp.float32(baselines.DEFAULT_V_B), jnp.asarray(rank))
        runs[name] = rollout(baselines.POLICIES[name], keys, params, policy_state=state, trace=True)
    result = {}
    for name, (m, tr) in runs.items():
        slots = int(round(float(m["mission_time"][0]) / float(params.tau)))
        q = np.concatenate([np.asarray(params.q0)[None], np.asarray(tr["q"][0, :slots])])
        result[name] = {"q": q, **{k: float(np.asarray(v)[0]) for k, v in m.items()}}
    return result


def _row(panel, policy, B, v_b, m) -> dict:
    row = {"panel": panel, "policy": policy, "bandwidth_hz": float(B), "v_b": v_b, "episodes": len(m["mean_psnr"])}
    for k in SUMMARY:
        x = np.asarray(m[k], np.float64)
        if k == "psnr_visited":  # defined only where something was covered (docs/model.md, eq. 8.1)
            x = x[np.asarray(m["coverage"]) > 0]
        row[k], row[f"{k}_ci95"] = mean_ci(x) if len(x) > 1 else (np.nan, np.nan)
    return row


def table(results: dict) -> list[dict]:
    """Rows of Fig. 2: panel 'a' (vs B, baselines at 8.9 m/s), 'b' (vs v_b at 25 kHz), 'grid' (all of B x v_b)."""
    Bs, vs = results["bandwidths"], results["velocities"]
    iv = vs.index(baselines.DEFAULT_V_B)
    ib = Bs.index(PANEL_B_BANDWIDTH)
    rows = []
    for name in ("greedy", "tsp"):
        r = results[name]
        pick = lambda i, j: {k: v[i, j] for k, v in r.items()}
        rows += [_row("a", name, B, baselines.DEFAULT_V_B, pick(i, iv)) for i, B in enumerate(Bs)]
        rows += [_row("b", name, PANEL_B_BANDWIDTH, v, pick(ib, j)) for j, v in enumerate(vs)]
        rows += [_row("grid", name, B, v, pick(i, j)) for i, B in enumerate(Bs) for j, v in enumerate(vs)]
    for i, B in enumerate(results["ddqn_bandwidths"]):
        m = {k: v[i] for k, v in results["DDQN"].items()}
        rows.append(_row("a", "DDQN", B, None, m))
        if B == PANEL_B_BANDWIDTH:
            rows.append(_row("b", "DDQN", B, None, m))
    return rows


def csv_text(rows: list[dict]) -> str:
    cols = list(rows[0])
    lines = [",".join(cols)]
    lines += [",".join("" if r[c] is None else str(r[c]) for c in cols) for r in rows]
    return "\n".join(lines) + "\n"


def markdown_table(rows: list[dict], panel: str = "a") -> str:
    """Panel rows as a Markdown table: mean PSNR ± 95 % CI, coverage, arrival."""
    out = ["| policy | B (kHz) | v_b (m/s) | mean PSNR (dB) | coverage | arrived |", "|---|---|---|---|---|---|"]
    for r in (r for r in rows if r["panel"] == panel):
        v = "—" if r["v_b"] is None else f"{r['v_b']:g}"
        out.append(
            f"| {r['policy']} | {r['bandwidth_hz'] / 1e3:g} | {v} | {r['mean_psnr']:.2f} ± {r['mean_psnr_ci95']:.2f} "
            f"| {r['coverage']:.2f} ± {r['coverage_ci95']:.2f} | {r['arrived']:.3f} |"
        )
    return "\n".join(out)
