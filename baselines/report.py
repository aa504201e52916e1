"""The reference table of docs/baselines.md: greedy and TSP at the paper's 8.9 m/s and at their
tuned speed v_b*, greedy-dwell and TSP-dwell at their tuned knobs, dwell-switch (those rules with
k* chosen by simulation during the flight), the open-loop planner, the exact receding-horizon
planner, plan-switch (the exact planner's every re-plan checked against the dwell rules by
simulation) and the certified bound, per bandwidth.

``semuav-baselines [--episodes 1000] [--validation-episodes 500] [--json out.json]`` (the command
line: ``semuav_jax.cli.baselines``).

v_b* and the dwell knobs (v_c, k*, margin) are chosen per bandwidth on the validation layouts
(``keys.VALIDATION_SEED``) from ``SPEED_GRID`` and ``DWELL_GRID`` as the best mean PSNR among the
settings that arrive in >= ``ARRIVAL_MIN`` of episodes, in one vmapped program per baseline (dwell-switch's
margin from ``SWITCH_MARGINS`` on ``SWITCH_TUNING`` of those layouts, at TSP-dwell's v_c); every
reported number comes from the test layouts (``keys.TEST_SEED``), the same episodes for every policy.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING

import jax
import numpy as np

from baselines import plan_switch, receding
from baselines.bound import psnr_bound
from baselines.dwell import DWELL_POLICIES, dwell_metrics, dwell_sweep, grid_points
from baselines.dwell_switch import dwell_switch_metrics
from baselines.evaluate import run, sweep, tsp_ranks
from baselines.planner import PLAN_SPEEDS, make_plans, planner, visit_options
from baselines.policies import DEFAULT_V_B
from baselines.travel_bound import flight_account, travel_bound
from semuav_jax.keys import TEST_SEED, VALIDATION_SEED, episode_keys
from semuav_jax.params import validate_params
from semuav_jax.sharding import map_episodes
from semuav_jax.stats import mean_ci, wilson_interval

if TYPE_CHECKING:
    from baselines.planner import PlanState
    from semuav_jax.params import EnvParams

SPEED_GRID = tuple(float(v) for v in range(6, 26))  # m/s, 6..25 in 1 m/s steps
BANDWIDTHS = (5e3, 20e3, 25e3, 40e3)  # Hz
ARRIVAL_MIN = 0.995
TUNED = ("greedy", "tsp")
DWELL_GRID = {
    "v_c": (22.0, 25.0),
    "k_star": (8.0, 16.0, 24.0, 32.0, 48.0, 64.0, 96.0, 128.0),
    "margin": (-6.0, -4.0, -2.0, 0.0, 2.0),
}  # m/s, symbols, s
SWITCH_MARGINS = (-2.0, 0.0)  # s: dwell-switch's candidates' margin, chosen per bandwidth
SWITCH_TUNING = 200  # validation layouts that choose it (each costs ~200 simulated episodes)


def best_arriving(psnr: np.ndarray, arrived: np.ndarray) -> np.ndarray:
    """Per bandwidth (rows), the setting (column) of best mean PSNR among those arriving in
    >= ``ARRIVAL_MIN`` of the validation layouts."""
    return np.argmax(np.where(arrived >= ARRIVAL_MIN, psnr, -np.inf), axis=1)


def tune(
    params: EnvParams,
    bandwidths: Sequence[float] = BANDWIDTHS,
    episodes: int = 500,
    grid: Sequence[float] = SPEED_GRID,
    workers: int = 2,
    switch: bool = True,
) -> dict:
    """v_b* per bandwidth for each of ``TUNED`` on the validation layouts, the dwell knobs, and
    (``switch``) dwell-switch's margin; with the grids' means."""
    keys = episode_keys(VALIDATION_SEED, episodes)
    rank = tsp_ranks(keys, params, workers=workers)
    out = {"grid": list(grid), "episodes": episodes, "dwell_grid": {k: list(v) for k, v in DWELL_GRID.items()}}
    for name in TUNED:
        m = sweep(name, keys, params, v_b=grid, B=bandwidths, rank=rank)
        psnr, arrived = m["mean_psnr"].mean(-1), m["arrived"].mean(-1)
        best = best_arriving(psnr, arrived)
        out[name] = {"v_star": [float(grid[i]) for i in best], "mean_psnr": psnr.tolist(), "arrived": arrived.tolist()}
    points = grid_points(*DWELL_GRID.values())
    for name in DWELL_POLICIES:
        m = dwell_sweep(name, keys, params, *DWELL_GRID.values(), B=bandwidths, rank=rank)
        psnr, arrived = m["mean_psnr"].mean(-1), m["arrived"].mean(-1)
        best = best_arriving(psnr, arrived)
        out[name] = {"knobs": [points[i] for i in best], "mean_psnr": psnr.tolist(), "arrived": arrived.tolist()}
    if not switch:
        return out
    n = min(episodes, SWITCH_TUNING)
    grid = [
        [
            switch_metrics(keys[:n], params.replace(B=b), out["tsp-dwell"]["knobs"][j][0], mg, rank[:n])
            for mg in SWITCH_MARGINS
        ]
        for j, b in enumerate(bandwidths)
    ]
    psnr = np.array([[m["mean_psnr"].mean() for m in row] for row in grid])
    arrived = np.array([[m["arrived"].mean() for m in row] for row in grid])
    best = best_arriving(psnr, arrived)
    out["dwell-switch"] = {
        "switch": [[out["tsp-dwell"]["knobs"][j][0], SWITCH_MARGINS[i]] for j, i in enumerate(best)],
        "episodes": n,
        "margins": list(SWITCH_MARGINS),
        "mean_psnr": psnr.tolist(),
        "arrived": arrived.tolist(),
    }
    return out


def certified_bound(keys: jax.Array, params: EnvParams) -> np.ndarray:
    """(E,) the certified bound per episode: the lower of the PSNR bound (``bound.psnr_bound``) and
    the travel bound of eq. 7.14 (``travel_bound.travel_bound``)."""
    return np.minimum(psnr_bound(keys, params), travel_bound(keys, params))


def switch_metrics(keys: jax.Array, params: EnvParams, v_c: float, margin: float, rank: np.ndarray) -> dict:
    """Dwell-switch's per-episode metrics, its episodes split over every device of every process."""
    return map_episodes(lambda part: dwell_switch_metrics(part[0], params, v_c, margin, part[1])[0], (keys, rank))


def flights(
    params: EnvParams,
    keys: jax.Array,
    tuned: dict,
    bandwidths: Sequence[float] = BANDWIDTHS,
    workers: int = 2,
    rank: np.ndarray | None = None,
    plans: Sequence[PlanState] | None = None,
    account: bool = False,
) -> list[dict]:
    """Per-episode metrics (dicts of (E,) arrays) on ``keys`` at each bandwidth: greedy and TSP at
    the paper's speed and at their tuned v_b* (``tuned`` from :func:`tune`), and the planner.
    ``rank`` (TSP ranks of ``keys``) and ``plans`` (one PlanState per bandwidth) are solved here
    unless given. ``account``: the exact planner's flights also measured against the bound's
    relaxation (``travel_bound.flight_account``), and so are plan-switch's (at dwell-switch's v_c and
    margin, when ``tuned`` has them)."""
    rank = tsp_ranks(keys, params, workers=workers) if rank is None else rank
    speeds = sorted({DEFAULT_V_B, *[v for n in TUNED for v in tuned[n]["v_star"]]})
    swept = {n: sweep(n, keys, params, v_b=speeds, B=bandwidths, rank=rank) for n in TUNED}
    out = []
    for j, b in enumerate(bandwidths):
        pb = params.replace(B=b)
        row = {}
        for n in TUNED:
            for label, v in ((f"{n} {DEFAULT_V_B:g}", DEFAULT_V_B), (f"{n} v_b*", tuned[n]["v_star"][j])):
                row[label] = {"v_b": v, **{k: x[j, speeds.index(v)] for k, x in swept[n].items()}}
        for n, policy in DWELL_POLICIES.items():
            v_c, k_star, margin = tuned[n]["knobs"][j]
            m = dwell_metrics(policy, keys, pb, v_c, k_star, margin, rank)
            row[n] = {"v_b": v_c, "knobs": [v_c, k_star, margin], **{k: np.asarray(x) for k, x in m.items()}}
        if "dwell-switch" in tuned:
            v_c, margin = tuned["dwell-switch"]["switch"][j]
            t1 = time.perf_counter()
            m = switch_metrics(keys, pb, v_c, margin, np.asarray(rank))
            row["dwell-switch"] = {"v_b": v_c, "switch": [v_c, margin], **m, "wall_s": time.perf_counter() - t1}
        t1 = time.perf_counter()
        plan = make_plans(keys, pb, workers=workers) if plans is None else plans[j]
        row["planner"] = {
            "v_b": None,
            **{k: np.asarray(v) for k, v in run(planner, keys, pb, plan).items()},
            "wall_s": time.perf_counter() - t1,
        }
        t1 = time.perf_counter()
        m, tr = receding.fly(keys, pb, workers=workers, trace=account)
        row["exact planner"] = {"v_b": None, **m, "wall_s": time.perf_counter() - t1}
        if account:
            row["exact planner"]["account"] = flight_account(jax.tree.map(np.asarray, tr), keys, pb)
        if "dwell-switch" in tuned:
            t1 = time.perf_counter()
            m, _, tr = plan_switch.fly(keys, pb, v_c, margin, np.asarray(rank), workers=workers, trace=account)
            row["plan-switch"] = {"v_b": None, "switch": [v_c, margin], **m, "wall_s": time.perf_counter() - t1}
            if account:
                row["plan-switch"]["account"] = flight_account(jax.tree.map(np.asarray, tr), keys, pb)
        out.append(row)
    return out


def summary(m: dict, T_s: float | None = None) -> dict:
    """Mean PSNR with its t interval, coverage and arrival with its Wilson interval of per-episode
    metrics; with the mission length ``T_s``, also the mean time left unused (T - mission time, s)."""
    mean, ci = mean_ci(m["mean_psnr"])
    arrived = np.asarray(m["arrived"], np.float64)
    lo, hi = wilson_interval(arrived.mean(), arrived.size)
    return {
        "mean_psnr": mean,
        "ci95": ci,
        "coverage": float(np.mean(m["coverage"])),
        "arrived": float(arrived.mean()),
        "arrived_wilson95": [float(lo), float(hi)],
    } | ({} if T_s is None else {"unused_s": float(np.mean(T_s - np.asarray(m["mission_time"], np.float64)))})


EXACT_VS = ("planner", "greedy-dwell", "tsp-dwell")  # the new planners' target: the best of these + 0.5 dB
SWITCH_VS = (*EXACT_VS, "exact planner")  # dwell-switch against the best of these
PLAN_SWITCH_VS = (*SWITCH_VS, "dwell-switch")  # plan-switch against the best of these


def reference_summary(m: dict, T_s: float | None = None) -> dict:
    """A row of the table: the policy's setting (v_b, dwell knobs or switch) and its :func:`summary`."""
    return {"v_b": m["v_b"], **{x: m[x] for x in ("knobs", "switch") if x in m}, **summary(m, T_s)}


def check_bandwidth(params: EnvParams, b: float, velocities: Iterable[float] = ()) -> None:
    """ValueError (one line), before any computation, unless the bandwidth ``b`` and the speeds give
    valid parameters and finite planner service times (a B so small that one image never arrives)."""
    at = params.replace(B=float(b))
    validate_params(at)
    for v in (*PLAN_SPEEDS, *velocities):
        with np.errstate(divide="ignore", over="ignore"):
            service = visit_options(min(float(v), float(at.v_max)), at)[2]
        if not np.all(np.isfinite(np.asarray(service, np.float32))):
            raise ValueError(
                f"bandwidth {b:g} Hz is too small for any image to arrive (the service time of a "
                "device is not finite in float32)"
            )


def report(
    params: EnvParams,
    bandwidths: Sequence[float] = BANDWIDTHS,
    episodes: int = 1000,
    validation_episodes: int = 500,
    workers: int = 2,
    log: Callable[[str], None] = print,
) -> dict:
    """Every number of the table (JSON-ready)."""
    t0 = time.perf_counter()
    tuned = tune(params, bandwidths, validation_episodes, workers=workers)
    log(
        f"v_b* and dwell knobs chosen on {validation_episodes} validation layouts ({time.perf_counter() - t0:.0f} s): "
        + ", ".join(f"{n} {tuned[n]['v_star']}" for n in TUNED)
        + "; "
        + ", ".join(f"{n} {tuned[n]['knobs']}" for n in DWELL_POLICIES)
    )
    keys = episode_keys(TEST_SEED, episodes)
    T_s = params.K * float(params.tau)
    rows = []
    for b, fl in zip(bandwidths, flights(params, keys, tuned, bandwidths, workers, account=True)):
        row = {
            "B": float(b),
            "policies": {k: reference_summary(m, T_s) for k, m in fl.items()},
        }
        for name in ("planner", "exact planner", "dwell-switch", "plan-switch"):
            row["policies"][name]["wall_s"] = fl[name]["wall_s"]
            row["policies"][name]["unserved"] = float(np.mean(params.N - np.asarray(fl[name]["coverage"])))
        row["planner_minus_tuned_greedy"] = mean_ci(fl["planner"]["mean_psnr"] - fl["greedy v_b*"]["mean_psnr"])
        best = max(EXACT_VS, key=lambda n: row["policies"][n]["mean_psnr"])
        row["exact_minus_best"] = {
            "vs": best,
            "diff": mean_ci(fl["exact planner"]["mean_psnr"] - fl[best]["mean_psnr"]),
        }
        for key, name, versus in (
            ("switch_minus_best", "dwell-switch", SWITCH_VS),
            ("plan_switch_minus_best", "plan-switch", PLAN_SWITCH_VS),
            ("plan_switch_minus_target", "plan-switch", EXACT_VS),
        ):
            rival = max(versus, key=lambda n: row["policies"][n]["mean_psnr"])
            row[key] = {"vs": rival, "diff": mean_ci(fl[name]["mean_psnr"] - fl[rival]["mean_psnr"])}
        pb = params.replace(B=b)
        t1 = time.perf_counter()
        bound = certified_bound(keys, pb)
        row["bound"] = float(bound.mean())
        row["bound_wall_s"] = time.perf_counter() - t1
        row["bound_minus_exact"] = mean_ci(bound - fl["exact planner"]["mean_psnr"])
        row["bound_minus_switch"] = mean_ci(bound - fl["dwell-switch"]["mean_psnr"])
        row["bound_minus_plan_switch"] = mean_ci(bound - fl["plan-switch"]["mean_psnr"])
        row["account"] = {
            name: {k: float(np.mean(v)) for k, v in fl[name].pop("account").items()}
            for name in ("exact planner", "plan-switch")
        }
        rows.append(row)
        d, ci = row["plan_switch_minus_target"]["diff"]
        log(
            f"B = {b / 1e3:g} kHz: plan-switch {row['policies']['plan-switch']['mean_psnr']:.2f} dB "
            f"({d:+.2f} ± {ci:.2f} vs {row['plan_switch_minus_target']['vs']}), bound {row['bound']:.2f} dB; "
            f"planner {fl['planner']['wall_s']:.0f} s, exact planner {fl['exact planner']['wall_s']:.0f} s, "
            f"plan-switch {fl['plan-switch']['wall_s']:.0f} s, bound {row['bound_wall_s']:.0f} s"
        )
    return {
        "episodes": episodes,
        "test_seed": TEST_SEED,
        "validation_seed": VALIDATION_SEED,
        "N": params.N,
        "arrival_min": ARRIVAL_MIN,
        "tuning": tuned,
        "rows": rows,
        "wall_s": time.perf_counter() - t0,
    }
