"""Wall time of the full Fig. 2 (a)+(b) baseline sweep: 8 bandwidths x 8 speeds x 2 policies x 200 layouts.

    python benchmarks/fig2_sweep.py [--devices 2] [--layouts 200]

Each policy's whole B x v_b grid is one compiled program (the TSP orders come from OR-Tools first).
Prints a table and writes ``benchmarks/fig2_sweep.json``. Target: under 60 s on the 2-core CPU.
"""

import argparse
import json
import os
import time
from pathlib import Path

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("--devices", type=int, default=os.cpu_count(), help="host CPU devices to shard the episodes over")
ap.add_argument("--layouts", type=int, default=200)
ap.add_argument("--out", default=str(Path(__file__).with_suffix(".json")))
args = ap.parse_args()
os.environ["XLA_FLAGS"] = (
    os.environ.get("XLA_FLAGS", "") + f" --xla_force_host_platform_device_count={args.devices}"
).strip()

import jax  # noqa: E402  (XLA_FLAGS must be set first)

from baselines import sweep, tsp_ranks  # noqa: E402
from semuav_jax.agents.scenarios import scenario_params  # noqa: E402
from semuav_jax.experiments.fig2 import BANDWIDTHS, VELOCITIES  # noqa: E402
from semuav_jax.io import atomic_write  # noqa: E402
from semuav_jax.sharding import shard_episodes  # noqa: E402


def main():
    params = scenario_params("random")
    keys = jax.random.split(jax.random.key(0), args.layouts)
    rows, t_all = [], time.perf_counter()
    for name in ("greedy", "tsp"):
        t0 = time.perf_counter()
        rank = shard_episodes(tsp_ranks(keys, params)) if name == "tsp" else None
        m = sweep(name, shard_episodes(keys), params, v_b=VELOCITIES, B=BANDWIDTHS, rank=rank)
        rows.append({"policy": name, "wall_s": time.perf_counter() - t0, "episodes": int(m["mean_psnr"].size)})
    total = time.perf_counter() - t_all
    print(f"{'policy':>8} {'episodes':>9} {'wall s':>8}")
    for r in rows:
        print(f"{r['policy']:>8} {r['episodes']:>9} {r['wall_s']:>8.1f}")
    print(f"total {total:.1f} s (compile, OR-Tools and {sum(r['episodes'] for r in rows) * params.K:,} env steps)")
    result = {
        "devices": jax.device_count(),
        "layouts": args.layouts,
        "bandwidths": BANDWIDTHS,
        "velocities": VELOCITIES,
        "rows": rows,
        "total_s": total,
    }
    atomic_write(args.out, json.dumps(result, indent=2).encode())


if __name__ == "__main__":
    main()
