"""Reproduce the paper's Fig. 2 into ``results/`` (docs/RESULTS.md): ``python eval.py --quick``.

Trains one DDQN per bandwidth (or takes ``train.py`` run folders with ``--runs``), sweeps the
greedy and TSP baselines over bandwidth x speed, and writes fig2a/b/c PNGs with the numbers
behind them (CSV, JSON): mean PSNR, coverage and arrival with 95 % confidence intervals over
``--layouts`` random layouts per point. The sweeps shard their episodes over every device JAX sees.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

class UsageError(Exception):
    """A bad option or folder: one line on stderr, exit code 2."""


def parse_args(argv=None):
    from semuav_jax.agents.ddqn import DDQNConfig
    from semuav_jax.paper import BANDWIDTHS, QUICK, VELOCITIES

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true",
                   help=f"a few minutes: bandwidths {QUICK['bandwidths']}, speeds {QUICK['velocities']}, each agent "
                        f"fine-tuned for {QUICK['total_steps']:,} steps from the shipped one (docs/RESULTS.md)")
    p.add_argument("--scratch", action="store_true", help="with --quick: train from random weights instead")
    p.add_argument("--out", default="results", help="output folder (default: %(default)s)")
    p.add_argument("--overwrite", action="store_true", help="replace the results in an existing --out")
    p.add_argument("--runs", nargs="+", default=None,
                   help="train.py run folders (their bandwidth and model) instead of training here")
    p.add_argument("--layouts", type=int, default=200, help="random layouts per point (default: %(default)s)")
    p.add_argument("--bandwidths", type=float, nargs="+", default=None, help=f"Hz (default: {BANDWIDTHS})")
    p.add_argument("--velocities", type=float, nargs="+", default=None, help=f"m/s (default: {VELOCITIES})")
    p.add_argument("--total-steps", type=int, default=None,
                   help=f"training env steps per agent (default: {DDQNConfig().total_steps:,})")
    p.add_argument("--reward-mode", choices=("paper", "gain"), default="gain")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--curves", default=None, help="PSNR curves .npz (default: the shipped DeepJSCC curves)")
    a = p.parse_args(argv)
    a.bandwidths = tuple(a.bandwidths or (QUICK["bandwidths"] if a.quick else BANDWIDTHS))
    a.velocities = tuple(a.velocities or (QUICK["velocities"] if a.quick else VELOCITIES))
    a.total_steps = a.total_steps or (QUICK["total_steps"] if a.quick else DDQNConfig().total_steps)
    if a.layouts < 2:
        raise UsageError(f"--layouts must be >= 2 for a confidence interval, got {a.layouts}")
    if min(a.bandwidths) <= 0 or min(a.velocities) <= 0:
        raise UsageError("--bandwidths and --velocities must be > 0")
    out = Path(a.out)
    if out.exists() and any(out.iterdir()) and not a.overwrite:
        raise UsageError(f"output folder {out} is not empty; pass --overwrite to replace its results")
    return a


def load_runs(folders, params):
    """BandwidthAgents from train.py run folders (seed 0 of each), sorted by bandwidth."""
    import jax

    from semuav_jax.agents.ddqn import DDQNConfig, make_train
    from semuav_jax.agents.pretrained import seed0_weights
    from semuav_jax.paper import BandwidthAgents

    runs = []
    for f in map(Path, folders):
        cfg_file, model_file = f / "config.json", f / "model.msgpack"
        if not cfg_file.is_file() or not model_file.is_file():
            raise UsageError(f"{f} is not a finished train.py run (needs config.json and model.msgpack)")
        cfg = json.loads(cfg_file.read_text())
        runs.append((float(cfg["bandwidth"]), seed0_weights(model_file.read_bytes()), DDQNConfig.from_dict(cfg["ddqn"])))
    runs.sort(key=lambda r: r[0])
    margins = {r[2].shield_margin for r in runs}
    if len(margins) > 1:
        raise UsageError(f"--runs: the agents use different shield margins {sorted(margins, key=str)}")
    network = make_train(runs[0][2], params).network
    stacked = jax.tree.map(lambda *xs: jax.numpy.stack(xs), *[r[1] for r in runs])
    return BandwidthAgents(network, stacked, tuple(r[0] for r in runs), curves={}, shield_margin=margins.pop())


def save_runs(agents, config, args, out: Path):
    """Each trained agent as a train.py-style run folder, so a later eval.py can reuse it with --runs."""
    import jax
    from flax import serialization

    from semuav_jax.io import atomic_write

    for i, b in enumerate(agents.bandwidths):
        folder = out / "runs" / f"B{int(b)}"
        folder.mkdir(parents=True, exist_ok=True)
        cfg = {"scenario": "random", "reward_mode": args.reward_mode, "bandwidth": b, "seeds": 1,
               "seed": args.seed, "curves": args.curves, "ddqn": config.to_dict()}
        atomic_write(folder / "config.json", json.dumps(cfg, indent=2).encode())
        net = jax.tree.map(lambda x: x[i : i + 1], agents.net_params)
        atomic_write(folder / "model.msgpack", serialization.to_bytes(net))


def main(argv=None) -> int:
    try:
        args = parse_args(argv)
    except UsageError as e:
        print(f"eval.py: error: {e}", file=sys.stderr)
        return 2

    import jax
    from tqdm import tqdm

    from semuav_jax import figures, paper
    from semuav_jax.agents.ddqn import DDQNConfig
    from semuav_jax.agents.pretrained import load_pretrained
    from semuav_jax.agents.scenarios import scenario_params
    from semuav_jax.curves import load_curves
    from semuav_jax.io import atomic_write

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    try:
        curves = load_curves(args.curves) if args.curves else None
        params = scenario_params("random", curves, reward_mode=args.reward_mode)
        fixed = scenario_params("fixed", curves, reward_mode=args.reward_mode)
        agents = load_runs(args.runs, params) if args.runs else None
    except (UsageError, ValueError, FileNotFoundError) as e:
        print(f"eval.py: error: {e}", file=sys.stderr)
        return 2
    print(f"JAX devices: {jax.device_count()} ({jax.devices()[0].platform})")
    timings = {}
    key = jax.random.key(args.seed)
    k_train, k_eval, k_traj = jax.random.split(key, 3)

    if agents is None:
        config, init = DDQNConfig(total_steps=args.total_steps), None
        if args.quick and not args.scratch:
            base, _, init = load_pretrained()
            config = dataclasses.replace(base, total_steps=args.total_steps, eps_start=paper.QUICK["eps_start"])
        t0 = time.time()
        what = "fine-tuning the shipped agent" if init is not None else "training"
        with tqdm(total=config.num_chunks, desc=f"{what} at {len(args.bandwidths)} bandwidths (vmapped)",
                  unit="chunk", dynamic_ncols=True) as bar:
            agents = paper.train_over_bandwidth(
                config, params, args.bandwidths, k_train, progress=bar.update, init_weights=init
            )
        timings["train_s"] = time.time() - t0
        save_runs(agents, config, args, out)
        figures.training_curves(agents, out / "training.png")

    keys = jax.random.split(k_eval, args.layouts)
    sweep_B = tuple(sorted(set(args.bandwidths) | {paper.PANEL_B_BANDWIDTH}))
    sweep_v = tuple(sorted(set(args.velocities) | {paper.baselines.DEFAULT_V_B}))
    t0 = time.time()
    results = {"bandwidths": sweep_B, "velocities": sweep_v, "layouts": args.layouts}
    for name in tqdm(("greedy", "tsp"), desc="baseline sweeps (B x v_b)", dynamic_ncols=True):
        results[name] = paper.baseline_sweep(name, keys, params, sweep_B, sweep_v)
    timings["baseline_sweep_s"] = time.time() - t0
    t0 = time.time()
    results["DDQN"] = paper.ddqn_sweep(agents, keys, params)
    results["ddqn_bandwidths"] = agents.bandwidths
    timings["ddqn_eval_s"] = time.time() - t0

    index_20k = min(range(len(agents.bandwidths)), key=lambda i: abs(agents.bandwidths[i] - 20e3))
    traj = paper.trajectories(agents, index_20k, fixed.replace(B=agents.bandwidths[index_20k]), k_traj)
    rows = paper.table(results)
    atomic_write(out / "fig2.csv", paper.csv_text(rows).encode())
    summary = {"rows": rows, "timings_s": timings, "devices": jax.device_count(),
               "trajectories": {k: {m: v for m, v in t.items() if m != "q"} for k, t in traj.items()},
               "trajectory_bandwidth": agents.bandwidths[index_20k], "args": vars(args)}
    atomic_write(out / "fig2.json", json.dumps(summary, indent=2, default=list).encode())
    figures.fig2a(rows, out / "fig2a.png")
    figures.fig2b(rows, out / "fig2b.png", paper.PANEL_B_BANDWIDTH)
    figures.fig2c(traj, fixed, out / "fig2c.png")
    print(paper.markdown_table(rows))
    print(f"wrote {out}/fig2a.png fig2b.png fig2c.png fig2.csv fig2.json ({timings})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
