"""Env-steps per second of the jitted, vmapped rollout (random policy), and of a plain NumPy loop.

    python benchmarks/env_throughput.py [--devices 2] [--envs 1 64 1024 4096 16384] [--repeats 3]

XLA:CPU runs each elementwise fusion on one thread, so the batch is sharded over ``--devices``
host CPU devices (one per core by default) with ``jax.sharding``. Prints a table and writes
``benchmarks/env_throughput.json``. Run it on a quiet machine: the figure is the best of the repeats.
"""

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("--devices", type=int, default=os.cpu_count(), help="host CPU devices to shard the batch over")
ap.add_argument("--envs", type=int, nargs="+", default=[1, 64, 1024, 4096, 16384])
ap.add_argument("--repeats", type=int, default=3)
ap.add_argument("--numpy-steps", type=int, default=5000, help="slots of the NumPy single-env loop")
ap.add_argument("--out", default=str(Path(__file__).with_suffix(".json")))
args = ap.parse_args()
os.environ["XLA_FLAGS"] = (
    os.environ.get("XLA_FLAGS", "") + f" --xla_force_host_platform_device_count={args.devices}"
).strip()

import jax  # noqa: E402  (XLA_FLAGS must be set first)
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from reference_numpy import NumpyEnv, params_dict  # noqa: E402

from semuav_jax.curves import load_curves, synthetic_curves  # noqa: E402
from semuav_jax.io import atomic_write  # noqa: E402
from semuav_jax.params import make_params  # noqa: E402
from semuav_jax.rollout import random_policy, random_policy_state, rollout  # noqa: E402
from semuav_jax.sharding import shard_episodes  # noqa: E402


def curves():
    try:
        return load_curves()
    except FileNotFoundError:
        return synthetic_curves(32)


def jax_steps_per_s(params, n_envs):
    keys = jax.random.split(jax.random.key(0), n_envs)
    draws = jax.vmap(random_policy_state, (0, None))(jax.random.split(jax.random.key(1), n_envs), params)
    keys, draws = shard_episodes((keys, draws))  # pads 1 env to one per device: count only n_envs
    t0 = time.perf_counter()
    jax.block_until_ready(rollout(random_policy, keys, params, policy_state=draws))
    compile_s = time.perf_counter() - t0
    best = float("inf")
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(rollout(random_policy, keys, params, policy_state=draws))
        best = min(best, time.perf_counter() - t0)
    return n_envs * params.K / best, compile_s


def numpy_steps_per_s(params):
    p, rng = params_dict(params), np.random.default_rng(0)
    env = NumpyEnv(p, params.C, rng.uniform(size=(params.N, 2)) * [p["Lx"], p["Ly"]], np.arange(params.N))
    t0 = time.perf_counter()
    for _ in range(args.numpy_steps):
        if env.done:
            env = NumpyEnv(p, params.C, env.dev_pos, env.dev_img)
        env.step(rng.uniform(-p["a_max"], p["a_max"], 2), rng.uniform())
    return args.numpy_steps / (time.perf_counter() - t0)


def main():
    params = make_params(curves())
    rows = []
    print(f"{'envs':>7} {'steps/s':>14} {'compile s':>10}")
    for n in args.envs:
        sps, comp = jax_steps_per_s(params, n)
        rows.append({"envs": n, "steps_per_s": sps, "compile_s": comp})
        print(f"{n:>7} {sps:>14,.0f} {comp:>10.1f}")
    np_sps = numpy_steps_per_s(params)
    best = max(r["steps_per_s"] for r in rows)
    print(f"NumPy single-env loop: {np_sps:,.0f} steps/s; best JAX / NumPy = {best / np_sps:,.0f}x")
    result = {
        "devices": len(jax.devices()),
        "cpu_count": os.cpu_count(),
        "machine": platform.machine(),
        "jax": jax.__version__,
        "K": params.K,
        "N": params.N,
        "repeats": args.repeats,
        "rows": rows,
        "numpy_steps_per_s": np_sps,
    }
    atomic_write(args.out, json.dumps(result, indent=2).encode())
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
