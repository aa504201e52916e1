"""Wall time of the offline planner on 1000 random layouts at B = 25 kHz: plan (exact orienteering
DP over 3 cruise speeds, in worker processes) and fly (one jitted, vmapped rollout).

    python benchmarks/planner.py [--layouts 1000] [--workers 2] [--repeats 3]

Prints a table and writes ``benchmarks/planner.json``. Target: 1000 layouts in <= 120 s on the
2-core CPU. The first repeat includes JAX compilation; the table shows every repeat.
"""

import argparse
import json
import time
from pathlib import Path

import jax
import numpy as np

from baselines.evaluate import run
from baselines.planner import make_plans, planner
from semuav_jax.io import atomic_write
from semuav_jax.keys import TEST_SEED, episode_keys
from semuav_jax.params import make_params

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("--layouts", type=int, default=1000)
ap.add_argument("--workers", type=int, default=2)
ap.add_argument("--repeats", type=int, default=3)
ap.add_argument("--out", default=str(Path(__file__).with_suffix(".json")))
args = ap.parse_args()

params = make_params(B=25e3)
keys = episode_keys(TEST_SEED, args.layouts)
rows = []
for r in range(args.repeats):
    t0 = time.perf_counter()
    plans = make_plans(keys, params, workers=args.workers)
    t1 = time.perf_counter()
    m = jax.tree.map(np.asarray, run(planner, keys, params, plans))
    t2 = time.perf_counter()
    rows.append({"plan_s": t1 - t0, "fly_s": t2 - t1, "total_s": t2 - t0,
                 "mean_psnr": float(m["mean_psnr"].mean()), "arrived": float(m["arrived"].mean())})
print(f"{args.layouts} layouts, B = 25 kHz, {args.workers} workers")
print("| repeat | plan (s) | fly (s) | total (s) | mean PSNR (dB) | arrival |")
print("|---|---|---|---|---|---|")
for i, r in enumerate(rows):
    print(f"| {i} | {r['plan_s']:.1f} | {r['fly_s']:.1f} | {r['total_s']:.1f} | {r['mean_psnr']:.2f} | {100 * r['arrived']:.1f} % |")
atomic_write(args.out, json.dumps({"layouts": args.layouts, "workers": args.workers, "runs": rows}, indent=2).encode())
