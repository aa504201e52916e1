"""The BS's tours (docs/model.md eq. 6.5, ``semuav_jax.tour``) against NumPy's Held-Karp: path length
over the shortest on uniform layouts of the default area, from q0 to q_fin, and microseconds per plan
in one vmapped batch, for the re-planned tour with 0 (nearest neighbour only) .. TOUR_MOVES improving
moves, and for the JAX Held-Karp (``shortest_path``, moves "exact").

    taskset -c 0 python benchmarks/tour.py [--layouts 2000]

Prints the table and writes ``benchmarks/tour.json``.
"""

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from baselines.tsp import distance_matrix, exact_orders
from semuav_jax.curves import load_curves
from semuav_jax.io import atomic_write
from semuav_jax.params import make_params
from semuav_jax.tour import TOUR_MOVES, shortest_path, tour_order

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("--layouts", type=int, default=2000)
ap.add_argument("--devices", type=int, default=10)
ap.add_argument("--out", default=str(Path(__file__).with_suffix(".json")))
args = ap.parse_args()

p = make_params(load_curves())
q0, qf = np.asarray(p.q0, float), np.asarray(p.q_fin, float)
pos = np.random.default_rng(0).uniform([0, 0], [float(p.Lx), float(p.Ly)], (args.layouts, args.devices, 2))
dist = distance_matrix(pos, q0, qf)


def lengths(orders: np.ndarray) -> np.ndarray:
    """Path lengths (E,) of the device orders (E, N) from q0 to q_fin."""
    nodes = np.concatenate(
        [np.zeros((len(orders), 1), int), orders + 1, np.full((len(orders), 1), args.devices + 1)], 1
    )
    return dist[np.arange(len(orders))[:, None], nodes[:, :-1], nodes[:, 1:]].sum(1)


best = lengths(exact_orders(dist))
rows = []
plans = {m: lambda x, m=m: tour_order(q0, x, jnp.ones(args.devices, bool), qf, m) for m in (0, 2, 4, TOUR_MOVES, 8)}
plans["exact"] = lambda x: shortest_path(q0, x, qf)
for moves, plan in plans.items():
    f = jax.jit(jax.vmap(plan))
    x = jnp.asarray(pos, jnp.float32)
    orders = np.asarray(f(x))
    t0 = time.perf_counter()
    for _ in range(5):
        f(x).block_until_ready()
    us = (time.perf_counter() - t0) / 5 / args.layouts * 1e6
    r = lengths(orders) / best - 1
    rows.append({"moves": moves, "excess_mean": float(r.mean()), "excess_p99": float(np.quantile(r, 0.99)),
                 "shortest": float(np.mean(r < 1e-5)), "us_per_plan": us})  # fmt: skip
print(f"{args.layouts} layouts of {args.devices} devices, {jax.device_count()} device(s)")
print("| moves | longer than shortest, mean | 99th percentile | shortest found | µs per plan |")
print("|---|---|---|---|---|")
for r in rows:
    print(f"| {r['moves']} | {100 * r['excess_mean']:.2f} % | {100 * r['excess_p99']:.1f} % | "
          f"{100 * r['shortest']:.0f} % | {r['us_per_plan']:.1f} |")  # fmt: skip
atomic_write(args.out, json.dumps({"layouts": args.layouts, "devices": args.devices, "rows": rows}, indent=1).encode())
