"""Wall time of the planners on 1000 random layouts at B = 25 kHz: the open-loop planner (plan once:
exact orienteering DP over 3 cruise speeds, in worker processes; fly one jitted, vmapped rollout)
the exact receding-horizon planner (plan, fly 12 s, re-plan from the current states, ...),
plan-switch (the exact planner with every re-plan checked against the 12 dwell rules by simulation;
its time includes the TSP tours the rules need) and the certified bound.

    python benchmarks/planner.py [--layouts 1000] [--workers 2] [--repeats 2]

Prints a table and writes ``benchmarks/planner.json``. Targets on the 2-core CPU: open loop
<= 120 s, receding horizon and plan-switch <= 180 s each for 1000 layouts. The first repeat includes JAX compilation.
"""

import argparse
import json
import time
from pathlib import Path

import jax
import numpy as np

from baselines import plan_switch, receding, tsp_ranks
from baselines.evaluate import run
from baselines.planner import make_plans, planner
from baselines.travel_bound import travel_bound
from semuav_jax.io import atomic_write
from semuav_jax.keys import TEST_SEED, episode_keys
from semuav_jax.params import make_params

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("--layouts", type=int, default=1000)
ap.add_argument("--workers", type=int, default=2)
ap.add_argument("--repeats", type=int, default=2)
ap.add_argument("--out", default=str(Path(__file__).with_suffix(".json")))
args = ap.parse_args()

params = make_params(B=25e3)
keys = episode_keys(TEST_SEED, args.layouts)
rows = []
for _ in range(args.repeats):
    t0 = time.perf_counter()
    plans = make_plans(keys, params, workers=args.workers)
    t1 = time.perf_counter()
    m = jax.tree.map(np.asarray, run(planner, keys, params, plans))
    t2 = time.perf_counter()
    e = receding.fly(keys, params, workers=args.workers)[0]
    t3 = time.perf_counter()
    rank = tsp_ranks(keys, params, workers=args.workers)
    p = plan_switch.fly(keys, params, 25.0, -2.0, rank, workers=args.workers)[0]
    t4 = time.perf_counter()
    b = travel_bound(keys, params)
    t5 = time.perf_counter()
    rows.append(
        {
            "plan_s": t1 - t0,
            "fly_s": t2 - t1,
            "open_loop_s": t2 - t0,
            "exact_s": t3 - t2,
            "plan_switch_s": t4 - t3,
            "bound_s": t5 - t4,
            "mean_psnr": float(m["mean_psnr"].mean()),
            "exact_mean_psnr": float(e["mean_psnr"].mean()),
            "plan_switch_mean_psnr": float(p["mean_psnr"].mean()),
            "bound": float(b.mean()),
            "arrived": float(m["arrived"].mean()),
            "exact_arrived": float(e["arrived"].mean()),
            "plan_switch_arrived": float(p["arrived"].mean()),
        }
    )
print(f"{args.layouts} layouts, B = 25 kHz, {args.workers} workers")
print(
    "| repeat | open loop: plan (s) | fly (s) | total (s) | exact planner (s) | plan-switch (s) | bound (s) "
    "| PSNR open loop / exact / plan-switch / bound (dB) |"
)
print("|---|---|---|---|---|---|---|---|")
for i, r in enumerate(rows):
    print(
        f"| {i} | {r['plan_s']:.1f} | {r['fly_s']:.1f} | {r['open_loop_s']:.1f} | {r['exact_s']:.1f} "
        f"| {r['plan_switch_s']:.1f} | {r['bound_s']:.1f} | {r['mean_psnr']:.2f} / {r['exact_mean_psnr']:.2f} / "
        f"{r['plan_switch_mean_psnr']:.2f} / {r['bound']:.2f} |"
    )
atomic_write(args.out, json.dumps({"layouts": args.layouts, "workers": args.workers, "runs": rows}, indent=2).encode())
