"""The paper's Fig. 2 from the seeds of one bandwidth-conditioned agent and the references
(docs/RESULTS.md).

(a) mean PSNR vs B: the agent (mean over seeds, t interval across seeds), greedy and TSP at 8.9 m/s
and at v_b*, greedy-dwell and TSP-dwell at their tuned knobs, dwell-switch, the open-loop and the
exact planner, plan-switch;
(b) at 25 kHz: greedy and TSP vs their speed v_b, with arrival; the others, at their own speed, as bands;
(c) the paper layout at 25 kHz: the trajectories, coloured by speed, with each device's dwell.

Every point uses the same test layouts (``keys.TEST_SEED``); v_b* is chosen on validation layouts
(``keys.VALIDATION_SEED``). ``experiments.behaviour`` measures what explains the numbers. Every
step is saved (``experiments.stages``); the numbers are the same bits on any number of devices and
processes (docs/scaling.md).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from baselines import DEFAULT_V_B, sweep, tsp_ranks
from baselines.dwell import DWELL_POLICIES
from baselines.planner import PlanState, make_plans
from baselines.report import flights, tune
from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.evaluate import seed_metrics
from semuav_jax.agents.network import QNetwork
from semuav_jax.experiments.behaviour import behaviour, path, summarize, traced_runs
from semuav_jax.experiments.stages import Stages
from semuav_jax.keys import TEST_SEED, VALIDATION_SEED, episode_keys
from semuav_jax.params import EnvParams
from semuav_jax.sharding import split_hosts
from semuav_jax.stats import mean_ci, pm

BANDWIDTHS = (5e3, 10e3, 15e3, 20e3, 25e3, 30e3, 35e3, 40e3)
VELOCITIES = (4.0, 6.0, DEFAULT_V_B, 11.0, 14.0, 17.0, 20.0, 24.0)
PANEL_B = 25e3
REFERENCES = (
    "greedy 8.9",
    "tsp 8.9",
    "greedy v_b*",
    "tsp v_b*",
    "greedy-dwell",
    "tsp-dwell",
    "dwell-switch",
    "planner",
    "exact planner",
    "plan-switch",
)  # the rows of panel (a) beside the agent, in the order of the tables and figures
FULL = {"bandwidths": BANDWIDTHS, "velocities": VELOCITIES, "layouts": 1000, "validation_layouts": 500}
QUICK = {
    "bandwidths": (5e3, 20e3, 25e3, 40e3),
    "velocities": (4.0, DEFAULT_V_B, 16.0, 24.0),
    "layouts": 300,
    "validation_layouts": 100,
}


def khz(b: float) -> str:
    """How a bandwidth names a step, a file and a key of the results: kHz, 6 significant digits."""
    return f"{b / 1e3:g}"


def check_bandwidths(bandwidths: Sequence[float]) -> None:
    """ValueError if two bandwidths of the grid (with the panels' PANEL_B) would share a name."""
    by_name: dict = {}
    for b in sorted(set(bandwidths) | {PANEL_B}):
        by_name.setdefault(khz(b), []).append(b)
    for name, bs in by_name.items():
        if len(bs) > 1:
            raise ValueError(
                f"--bandwidths {' and '.join(f'{b!r}' for b in bs)} would both be named {name} kHz: "
                "give bandwidths that differ in their first 6 digits"
            )


def stage_count(grid: dict) -> int:
    """How many steps :func:`run` logs for ``grid`` (a progress bar's total)."""
    sweep_B = set(grid["bandwidths"]) | {PANEL_B}
    return 6 + len(sweep_B) + len({min(sweep_B), PANEL_B})


def _plan_dict(plan: PlanState) -> dict[str, np.ndarray]:
    return {f: np.asarray(getattr(plan, f)) for f in plan.__dataclass_fields__}


def shared_plans(keys: jax.Array, params: EnvParams, workers: int = 2) -> PlanState:
    """``make_plans`` of the episodes ``keys``, each process planning its share (one plan per episode)."""
    plan = split_hosts(lambda lo, hi: _plan_dict(make_plans(keys[lo:hi], params, workers=workers)), len(keys))
    return PlanState(**{k: jnp.asarray(v) for k, v in plan.items()})


def run(
    network: QNetwork,
    nets: Any,
    config: DDQNConfig,
    params: EnvParams,
    fixed: EnvParams,
    grid: dict,
    workers: int = 2,
    log: Callable[[str], None] = print,
    stages: Stages | None = None,
) -> dict:
    """Every number and path of Fig. 2 (JSON-ready except the paths' arrays). ``stages`` saves each
    step so that an interrupted run resumes (default: nothing saved)."""
    check_bandwidths(grid["bandwidths"])
    stage = stages or Stages(None, {}, log)
    log = stage.log
    bandwidths, velocities = tuple(grid["bandwidths"]), tuple(grid["velocities"])
    sweep_B = tuple(sorted(set(bandwidths) | {PANEL_B}))
    keys = episode_keys(TEST_SEED, grid["layouts"])
    tuned = stage(
        "v_b* on validation layouts",
        lambda: tune(params, sweep_B, grid["validation_layouts"], workers=workers),
        describe=lambda t: ": " + ", ".join(f"{n} {t[n]['v_star']}" for n in ("greedy", "tsp")),
    )
    # the TSP order does not depend on B: solved once
    rank = stage("TSP tours", lambda: np.asarray(tsp_ranks(keys, params, workers=workers)))
    plans = [
        stage(
            f"planner at {khz(b)} kHz",
            lambda b=b: shared_plans(keys, params.replace(B=b), workers),
            save=_plan_dict,
            load=lambda d: PlanState(**{k: jnp.asarray(v) for k, v in d.items()}),
        )
        for b in sweep_B
    ]
    refs = stage(
        "references flown (greedy, TSP at 8.9 m/s and v_b*; greedy-dwell, TSP-dwell, dwell-switch; "
        "the planners, plan-switch)",
        lambda: [  # without the planners' wall times: a saved step holds numbers that do not depend on the load
            {name: {k: v for k, v in m.items() if k != "wall_s"} for name, m in row.items()}
            for row in flights(params, keys, tuned, sweep_B, workers, rank=rank, plans=plans)
        ],
    )
    agent = stage("agent evaluated", lambda: seed_metrics(network, nets, config, keys, params, sweep_B))
    out = {
        "layouts": len(keys),
        "test_seed": TEST_SEED,
        "validation_seed": VALIDATION_SEED,
        "validation_layouts": grid["validation_layouts"],
        "tuning": tuned,
        "bandwidths": list(sweep_B),
        "velocities": list(velocities),
        "seeds": int(agent["mean_psnr"].shape[0]),
        "panel_a": [],
        "panel_b": {},
    }
    for j, b in enumerate(sweep_B):
        row = {"B": b, "agent_seeds": [float(x) for x in agent["mean_psnr"][:, j].mean(-1)]}
        row["agent"] = mean_ci(row["agent_seeds"])
        row["agent_coverage"] = float(agent["coverage"][:, j].mean())
        row["agent_arrived"] = float(agent["arrived"][:, j].mean())
        row["agent_shield_share"] = float(agent["shield_share"][:, j].mean())
        for name, m in refs[j].items():
            row[name] = {
                "v_b": m["v_b"],
                "mean_psnr": mean_ci(m["mean_psnr"]),
                "coverage": float(np.mean(m["coverage"])),
                "arrived": float(np.mean(m["arrived"])),
            }
            row[f"agent minus {name}"] = mean_ci(
                [mean_ci(agent["mean_psnr"][s, j] - m["mean_psnr"])[0] for s in range(out["seeds"])]
            )
        out["panel_a"].append(row)
    out["panel_b"] = stage("panel (b) swept", lambda: panel_b(keys, params, velocities, rank))
    out["behaviour"] = {}
    for b in sorted({min(sweep_B), PANEL_B}):
        ib = sweep_B.index(b)
        tuned_at_b = (
            {n: tuned[n]["v_star"][ib] for n in ("greedy", "tsp")}
            | {n: tuned[n]["knobs"][ib] for n in DWELL_POLICIES}
            | {"dwell-switch": tuned["dwell-switch"]["switch"][ib]}
        )
        at_b = params.replace(B=b)

        def measure(at_b: EnvParams = at_b, tuned_at_b: dict = tuned_at_b, ib: int = ib) -> dict:
            runs = traced_runs(network, nets, config, keys, at_b, tuned_at_b, workers, rank=rank, plan=plans[ib])
            return {name: summarize(behaviour(tr, at_b)) for name, (_, tr) in runs.items()}

        out["behaviour"][f"{khz(b)} kHz"] = stage(f"behaviour at {khz(b)} kHz", measure)
    pf = fixed.replace(B=PANEL_B)
    one = episode_keys(TEST_SEED, 1)
    paths = traced_runs(network, jax.tree.map(lambda x: x[:1], nets), config, one, pf, tuned_at_b, workers=1)
    out["paths"] = {
        name.replace(" seed 0", ""): path(tr, m, 0, pf)
        for name, (m, tr) in paths.items()
        if not name.endswith(f"{DEFAULT_V_B:g}")
    }
    log("paths on the paper layout")
    return out


def panel_b(keys: jax.Array, params: EnvParams, velocities: Sequence[float], rank: np.ndarray) -> dict:
    """Panel (b): greedy and TSP at B = PANEL_B vs their speed v_b: mean PSNR, arrival, coverage,
    symbols per covered device."""
    pb = params.replace(B=PANEL_B)
    out = {}
    for name in ("greedy", "tsp"):
        m = sweep(name, keys, pb, v_b=velocities, B=(PANEL_B,), rank=rank if name == "tsp" else None)
        per = lambda k, m=m: [m[k][0, i] for i in range(len(velocities))]
        out[name] = {
            "mean_psnr": [mean_ci(x) for x in per("mean_psnr")],
            "arrived": [float(x.mean()) for x in per("arrived")],
            "coverage": [float(x.mean()) for x in per("coverage")],
            # mean share of M received by a covered device
            "symbols_per_covered": [
                float((f * pb.N).sum() / max(c.sum(), 1)) for f, c in zip(per("symbol_fraction"), per("coverage"))
            ],
            "episodes": len(keys),
        }
    return out


def markdown(r: dict) -> str:
    """The tables of docs/RESULTS.md: panel (a) with the agent's margins, panel (b), and the behaviour at 25 kHz."""
    refs = REFERENCES
    margins = ("tsp v_b*", "tsp-dwell", "dwell-switch", "plan-switch")
    lines = [
        f"{r['layouts']} test layouts (seed {r['test_seed']}); DDQN: mean of {r['seeds']} seeds ± t interval "
        f"across seeds; references ± 95 % interval over layouts; v_b* from {r['validation_layouts']} validation "
        f"layouts (seed {r['validation_seed']}).",
        "",
        "| B (kHz) | DDQN (dB) | " + " | ".join(refs) + " | " + " | ".join(f"DDQN − {n}" for n in margins) + " |",
        "|---" * (2 + len(refs) + len(margins)) + "|",
    ]
    for row in r["panel_a"]:
        cells = [f"{row[n]['mean_psnr'][0]:.2f}" + (f" ({row[n]['v_b']:g} m/s)" if "v_b*" in n else "") for n in refs]
        diffs = [f"{row[f'agent minus {n}'][0]:+.2f} {pm(row[f'agent minus {n}'][1])}" for n in margins]
        lines.append(
            f"| {row['B'] / 1e3:g} | {row['agent'][0]:.2f} {pm(row['agent'][1])} | " + " | ".join(cells + diffs) + " |"
        )
    lines += [
        "",
        "Arrival: "
        + ", ".join(
            f"{row['B'] / 1e3:g} kHz DDQN {100 * row['agent_arrived']:.1f} % "
            f"(shield {100 * row['agent_shield_share']:.1f} % of slots)"
            for row in r["panel_a"]
        ),
        "",
        "| v_b (m/s), B = 25 kHz | " + " | ".join(f"{v:g}" for v in r["velocities"]) + " |",
        "|---" * (1 + len(r["velocities"])) + "|",
    ]
    for name, p in r["panel_b"].items():
        lines.append(f"| {name} PSNR (dB) | " + " | ".join(f"{m:.2f}" for m, _ in p["mean_psnr"]) + " |")
        lines.append(f"| {name} arrival | " + " | ".join(f"{100 * a:.1f} %" for a in p["arrived"]) + " |")
        lines.append(f"| {name} coverage | " + " | ".join(f"{c:.2f}" for c in p["coverage"]) + " |")
        lines.append(
            f"| {name} symbols per covered device (share of M) | "
            + " | ".join(f"{c:.2f}" for c in p["symbols_per_covered"])
            + " |"
        )
    keys = (
        "speed_transmitting",
        "speed_otherwise",
        "dwell_per_served_s",
        "symbols_per_served",
        "coverage",
        "mission_time_s",
    )
    for where, rows in r["behaviour"].items():
        lines += [
            "",
            f"Behaviour at B = {where} (means over the test layouts):",
            "",
            "| policy | speed while a device transmits (m/s) | speed otherwise (m/s) | seconds in range per "
            "served device | symbols per served device (share of M) | devices covered | mission time (s) |",
            "|---" * 7 + "|",
        ]
        for name, b in rows.items():
            lines.append(f"| {name} | " + " | ".join(f"{b[k][0]:.2f}" for k in keys) + " |")
    return "\n".join(lines)
