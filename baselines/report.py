"""Baseline report: greedy, TSP and straight flight on random default layouts (MODEL.md sections 7-8).

``python -m baselines.report [--episodes 1000] [--json out.json] [--synthetic]`` prints the mean
PSNR, coverage and arrival of each baseline at the default bandwidth and speed, a bandwidth and
a speed sweep on the same episodes, and the OR-Tools time per layout; ``--json`` writes them.
Uses the shipped DeepJSCC curves unless ``--curves`` or ``--synthetic`` says otherwise.
"""

from __future__ import annotations

import argparse
import json
import time

import jax
import numpy as np

from baselines.evaluate import sweep, tsp_ranks
from baselines.policies import DEFAULT_V_B, POLICIES
from baselines.tsp import DEFAULT_TIME_LIMIT_MS
from semuav_jax.curves import load_curves, synthetic_curves
from semuav_jax.params import make_params

BANDWIDTHS = (5e3, 10e3, 20e3, 40e3)
SPEEDS = (4.0, DEFAULT_V_B, 14.0, 20.0, 24.0)


def _summary(m: dict) -> dict:
    covered = m["coverage"] > 0
    return {
        "mean_psnr": float(m["mean_psnr"].mean()),
        "mean_psnr_sem": float(m["mean_psnr"].std(ddof=1) / np.sqrt(m["mean_psnr"].size)),
        "coverage": float(m["coverage"].mean()),
        "psnr_visited": float(m["psnr_visited"][covered].mean()) if covered.any() else None,
        "arrived": float(m["arrived"].mean()),
        "mission_time": float(m["mission_time"].mean()),
    }


def report(params, episodes: int, seed: int, time_limit_ms: int, workers: int) -> dict:
    """All numbers of the report (JSON-ready); every policy and sweep point uses the same episodes."""
    keys = jax.random.split(jax.random.PRNGKey(seed), episodes)
    t0 = time.perf_counter()
    rank = tsp_ranks(keys, params, time_limit_ms=time_limit_ms, workers=workers)
    tsp_seconds = time.perf_counter() - t0
    B = sorted(set(BANDWIDTHS) | {float(params.B)})
    i_b, i_v = B.index(float(params.B)), SPEEDS.index(DEFAULT_V_B)
    out = {
        "episodes": episodes, "seed": seed, "B": float(params.B), "v_b": DEFAULT_V_B, "N": params.N,
        "ortools": {"time_limit_ms": time_limit_ms, "workers": workers, "wall_s_per_layout": tsp_seconds / episodes},
        "baselines": {}, "bandwidth_sweep": {"B": B}, "speed_sweep": {"v_b": list(SPEEDS)},
    }
    for name in POLICIES:
        m = sweep(name, keys, params, v_b=SPEEDS, B=B, rank=rank)
        out["baselines"][name] = _summary({k: v[i_b, i_v] for k, v in m.items()})
        out["bandwidth_sweep"][name] = [_summary({k: v[j, i_v] for k, v in m.items()}) for j in range(len(B))]
        out["speed_sweep"][name] = [_summary({k: v[i_b, j] for k, v in m.items()}) for j in range(len(SPEEDS))]
    return out


def markdown(r: dict) -> str:
    """The report as Markdown tables."""
    lines = [
        f"{r['episodes']} random layouts (seed {r['seed']}), N = {r['N']}, B = {r['B'] / 1e3:g} kHz, v_b = {r['v_b']} m/s",
        "",
        "| baseline | mean PSNR (dB) | coverage (devices) | PSNR of covered (dB) | arrival | mission time (s) |",
        "|---|---|---|---|---|---|",
    ]
    for name, s in r["baselines"].items():
        lines.append(
            f"| {name} | {s['mean_psnr']:.2f} ± {s['mean_psnr_sem']:.2f} | {s['coverage']:.2f} | "
            f"{s['psnr_visited']:.2f} | {100 * s['arrived']:.1f} % | {s['mission_time']:.1f} |"
        )
    for title, axis, unit, scale in (("bandwidth_sweep", "B", "kHz", 1e-3), ("speed_sweep", "v_b", "m/s", 1.0)):
        sw = r[title]
        lines += ["", f"Mean PSNR (dB) / arrival over {axis} ({unit}):", ""]
        lines.append("| baseline | " + " | ".join(f"{x * scale:g}" for x in sw[axis]) + " |")
        lines.append("|---" * (len(sw[axis]) + 1) + "|")
        for name in r["baselines"]:
            lines.append(f"| {name} | " + " | ".join(f"{s['mean_psnr']:.2f} / {100 * s['arrived']:.0f} %" for s in sw[name]) + " |")
    o = r["ortools"]
    lines += ["", f"OR-Tools: {1e3 * o['wall_s_per_layout']:.0f} ms wall per layout "
                  f"({o['time_limit_ms']} ms guided local search, {o['workers']} workers)"]
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--B", type=float, default=20e3, help="bandwidth of the main table (Hz)")
    ap.add_argument("--curves", help="PSNR curves file (default: the shipped DeepJSCC curves)")
    ap.add_argument("--synthetic", action="store_true", help="use synthetic stand-in curves instead")
    ap.add_argument("--time-limit-ms", type=int, default=DEFAULT_TIME_LIMIT_MS)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", help="write the report here")
    args = ap.parse_args(argv)
    curves = synthetic_curves() if args.synthetic else load_curves(args.curves)
    r = report(make_params(curves, B=args.B), args.episodes, args.seed, args.time_limit_ms, args.workers)
    r["curves"] = "synthetic (tests/conftest.py formula)" if args.synthetic else (args.curves or "shipped DeepJSCC")
    print(f"curves: {r['curves']}")
    print(markdown(r))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(r, f, indent=2)


if __name__ == "__main__":
    main()
