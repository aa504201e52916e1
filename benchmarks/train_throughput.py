"""Environment steps per second during DDQN training (1 and 8 seeds in one compiled program).

Times one compiled segment of the default training configuration (after a warm-up call that
compiles it) and prints a table; writes benchmarks/train_throughput.json. Run it on a quiet
machine: ``python benchmarks/train_throughput.py [--seeds 1 8] [--chunks 4]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import jax

from semuav_jax.agents.ddqn import DDQNConfig, make_train
from semuav_jax.agents.scenarios import scenario_params
from semuav_jax.curves import synthetic_curves


def measure(seeds: int, chunks: int, scenario: str) -> dict:
    params = scenario_params(scenario, synthetic_curves())
    config = DDQNConfig()
    trainer = make_train(config, params)
    keys = jax.random.split(jax.random.PRNGKey(0), seeds)
    state = jax.jit(jax.vmap(trainer.init))(keys)
    run = jax.jit(jax.vmap(lambda s: trainer.run(s, chunks)))
    t0 = time.perf_counter()
    state, m = run(state)
    jax.block_until_ready(m)
    compile_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    state, m = run(state)
    jax.block_until_ready(m)
    dt = time.perf_counter() - t0
    steps = seeds * chunks * config.steps_per_chunk * config.num_envs
    updates = seeds * chunks * config.steps_per_chunk * config.updates_per_step
    return {"seeds": seeds, "env_steps": steps, "seconds": dt, "env_steps_per_s": steps / dt,
            "updates_per_s": updates / dt, "first_call_s": compile_s}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 8])
    ap.add_argument("--chunks", type=int, default=4, help="chunks per timed segment")
    ap.add_argument("--scenario", choices=("fixed", "random"), default="random")
    ap.add_argument("--out", default=str(Path(__file__).with_suffix(".json")))
    args = ap.parse_args()
    rows = [measure(s, args.chunks, args.scenario) for s in args.seeds]
    print(f"{'seeds':>5} {'env steps/s':>12} {'updates/s':>10} {'timed s':>8} {'1st call s':>10}")
    for r in rows:
        print(f"{r['seeds']:>5} {r['env_steps_per_s']:>12,.0f} {r['updates_per_s']:>10,.0f} {r['seconds']:>8.1f} "
              f"{r['first_call_s']:>10.1f}")
    info = {"config": DDQNConfig().to_dict(), "scenario": args.scenario, "cpu_count": os.cpu_count(),
            "load_avg": os.getloadavg(), "platform": platform.platform(), "jax": jax.__version__, "rows": rows}
    Path(args.out).write_text(json.dumps(info, indent=2))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
