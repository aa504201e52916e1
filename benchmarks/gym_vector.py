"""Env steps per second through Gymnasium's and SB3's APIs: the jitted, vmapped ``SemUAVVectorEnv``
(and ``SemUAVVecEnv``, its SB3 wrapper) against n single ``SemUAVGymEnv`` stepped in a Python loop
(SB3's ``DummyVecEnv`` when SB3 is installed, else Gymnasium's ``SyncVectorEnv``).

    python benchmarks/gym_vector.py [--envs 1 16 256 4096] [--seconds 2] [--repeats 3]

Every step goes through ``step(actions)`` with NumPy actions in and NumPy observations, rewards
and infos out, so the host transfer is included; random table actions, default parameters
(K = 250, N = 10). Prints a table and writes ``benchmarks/gym_vector.json``; each figure is the
best of the repeats, and under it ("burst") the best rate over 50 ms bursts within them.
"""

import argparse
import json
import os
import platform
import time
from pathlib import Path

import gymnasium
import jax
import numpy as np

from semuav_jax.curves import load_curves, synthetic_curves
from semuav_jax.gym_adapter import SemUAVGymEnv
from semuav_jax.gym_vector import SemUAVVectorEnv
from semuav_jax.io import atomic_write

try:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from semuav_jax.sb3 import SemUAVVecEnv
except ImportError:
    DummyVecEnv = SemUAVVecEnv = None

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("--envs", type=int, nargs="+", default=[1, 16, 256, 4096])
ap.add_argument("--loop-max-envs", type=int, default=256, help="largest n for the Python loop of single envs")
ap.add_argument("--seconds", type=float, default=2.0, help="timed seconds per measurement (after a warm-up)")
ap.add_argument("--repeats", type=int, default=3)
ap.add_argument("--out", default=str(Path(__file__).with_suffix(".json")))
args = ap.parse_args()
BURST_S = 0.05  # seconds per burst


def curves():
    try:
        return load_curves()
    except FileNotFoundError:
        return synthetic_curves(32)


def steps_per_s(step, n: int) -> tuple[float, float]:
    """(best over the repeats of n * steps / seconds, calling ``step(actions)`` for ``args.seconds``;
    the best such rate over the ``BURST_S`` bursts within them). On a machine shared with other
    work the first is what a learner gets; the second estimates the uncontested cost of a step."""
    rng = np.random.default_rng(0)
    actions = rng.integers(0, 9, (64, n))
    for i in range(3):  # compile and warm up
        step(actions[i])
    best = burst = 0.0
    for _ in range(args.repeats):
        done, t0 = 0, time.perf_counter()
        b_done, b0 = 0, t0
        while (elapsed := time.perf_counter() - t0) < args.seconds:
            step(actions[done % 64])
            done += 1
            b_done += 1
            if (now := time.perf_counter()) - b0 >= BURST_S:
                burst, b_done, b0 = max(burst, n * b_done / (now - b0)), 0, now
        best = max(best, n * done / elapsed)
    return best, max(burst, best)


def main():
    load_at_start = os.getloadavg()
    c = curves()
    loop_name = "DummyVecEnv" if DummyVecEnv else "SyncVectorEnv"
    rows = []
    print(f"{'envs':>6} {'SemUAVVectorEnv':>16} {'SemUAVVecEnv (SB3)':>19} {loop_name + ' loop':>18} {'speed-up':>9}")
    for n in args.envs:
        vec = SemUAVVectorEnv(num_envs=n, curves=c)
        vec.reset(seed=0)
        row = {"envs": n}
        row["vector_env"], row["vector_env_best_burst"] = steps_per_s(vec.step, n)
        if SemUAVVecEnv:
            sb3 = SemUAVVecEnv(num_envs=n, curves=c)
            sb3.reset()
            row["sb3_vec_env"], row["sb3_vec_env_best_burst"] = steps_per_s(sb3.step, n)
        if n <= args.loop_max_envs:
            if DummyVecEnv:
                loop = DummyVecEnv([lambda: SemUAVGymEnv(curves=c)] * n)
                loop.reset()
            else:
                loop = gymnasium.vector.SyncVectorEnv([lambda: SemUAVGymEnv(curves=c)] * n)
                loop.reset(seed=0)
            row["single_env_loop"], row["single_env_loop_best_burst"] = steps_per_s(loop.step, n)
            row["speed_up"] = row["vector_env"] / row["single_env_loop"]
            row["speed_up_best_burst"] = row["vector_env_best_burst"] / row["single_env_loop_best_burst"]
        rows.append(row)
        fmt = lambda k, w, row=row: f"{row[k]:>{w},.0f}" if k in row else f"{'-':>{w}}"
        for tail, label in (("", f"{n:>6}"), ("_best_burst", f"{'burst':>6}")):
            up = f"{row['speed_up' + tail]:>8,.0f}x" if "speed_up" in row else f"{'-':>9}"
            cells = [fmt("vector_env" + tail, 16), fmt("sb3_vec_env" + tail, 19), fmt("single_env_loop" + tail, 18)]
            print(label, *cells, up)
    result = {
        "cpu_count": os.cpu_count(),
        "machine": platform.machine(),
        "jax": jax.__version__,
        "gymnasium": gymnasium.__version__,
        "loop": loop_name,
        "seconds": args.seconds,
        "repeats": args.repeats,
        "load_average_at_start": load_at_start,
        "load_average_at_end": os.getloadavg(),
        "rows": rows,
    }
    atomic_write(args.out, json.dumps(result, indent=2).encode())
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
