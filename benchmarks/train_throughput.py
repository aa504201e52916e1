"""Environment steps and gradient updates per second during DDQN training, seeds vmapped in one
compiled program, for the default agent and the paper preset (docs/performance.md).

Times one compiled segment of ``train.py``'s configuration (after a warm-up call that compiles
it) and prints a table; writes benchmarks/train_throughput.json. Run it on a quiet machine:
``python benchmarks/train_throughput.py [--seeds 1 3] [--chunks 4] [--buffers ring flashbax]``.
``--buffers flashbax`` trains with flashbax's item buffer in place of our ring buffer (needs
``pip install flashbax``; it is not a dependency of the package).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import jax

from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.replay import ring_buffer
from semuav_jax.agents.run_config import PRESETS, RunConfig
from semuav_jax.agents.trainer import make_train
from semuav_jax.io import atomic_write


def replay_buffer(name: str, config: DDQNConfig):
    """The replay memory ``name``: ours (``ring``) or flashbax's uniform item buffer."""
    if name == "ring":
        return ring_buffer(config.buffer_size, config.batch_size)
    import flashbax

    return flashbax.make_item_buffer(
        max_length=config.buffer_size,
        min_length=config.batch_size,
        sample_batch_size=config.batch_size,
        add_batches=True,
    )


def measure(seeds: int, chunks: int, preset: str, buffer: str = "ring") -> dict:
    run = RunConfig.from_preset(preset)
    params, config = run.env_params(), run.agent
    trainer = make_train(config, params, buffer=replay_buffer(buffer, config))
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
    return {
        "preset": preset,
        "buffer": buffer,
        "seeds": seeds,
        "env_steps": steps,
        "seconds": dt,
        "env_steps_per_s": steps / dt,
        "updates_per_s": updates / dt,
        "first_call_s": compile_s,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 3])
    ap.add_argument("--chunks", type=int, default=4, help="chunks per timed segment")
    ap.add_argument("--presets", nargs="+", choices=sorted(PRESETS), default=["default", "paper"])
    ap.add_argument(
        "--buffers",
        nargs="+",
        choices=["ring", "flashbax"],
        default=["ring"],
        help="replay memories to time (flashbax: pip install flashbax)",
    )
    ap.add_argument("--out", default=str(Path(__file__).with_suffix(".json")))
    args = ap.parse_args()
    rows = [measure(s, args.chunks, p, b) for p in args.presets for b in args.buffers for s in args.seeds]
    print(
        f"{'preset':>8} {'buffer':>8} {'seeds':>5} {'env steps/s':>12} {'updates/s':>10} {'timed s':>8} "
        f"{'1st call s':>10}"
    )
    for r in rows:
        print(
            f"{r['preset']:>8} {r['buffer']:>8} {r['seeds']:>5} {r['env_steps_per_s']:>12,.0f} "
            f"{r['updates_per_s']:>10,.0f} {r['seconds']:>8.1f} {r['first_call_s']:>10.1f}"
        )
    info = {
        "config": DDQNConfig().to_dict(),
        "presets": PRESETS,
        "cpu_count": os.cpu_count(),
        "load_avg": os.getloadavg(),
        "platform": platform.platform(),
        "jax": jax.__version__,
        "rows": rows,
    }
    atomic_write(args.out, json.dumps(info, indent=2).encode())
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
