"""The reference table of the baselines per bandwidth (docs/baselines.md), printed as Markdown.

``semuav-baselines`` (or ``python -m semuav_jax.cli.baselines``): greedy and TSP at 8.9 m/s and at v_b*,
greedy-dwell and TSP-dwell, both planners and the certified bound, computed by ``baselines.report``;
``--json`` also saves every number.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from baselines.report import BANDWIDTHS, check_bandwidth, report
from baselines.report_table import markdown
from semuav_jax import distributed
from semuav_jax.curves import load_curves
from semuav_jax.io import atomic_write, check_writable_folder
from semuav_jax.params import make_params


def main(argv: list[str] | None = None) -> None:
    distributed.guarded(_main, argv)


def _main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=1000, help="test layouts")
    ap.add_argument("--validation-episodes", type=int, default=500, help="layouts that choose v_b*")
    ap.add_argument("--B", type=float, nargs="+", default=list(BANDWIDTHS), help="bandwidths (Hz)")
    ap.add_argument("--curves", help="PSNR curves file (default: the shipped DeepJSCC curves)")
    ap.add_argument("--workers", type=int, default=2, help="processes for OR-Tools and the planner")
    ap.add_argument("--json", help="write the report here")
    distributed.add_options(ap)
    args = ap.parse_args(argv)
    for name, lo in (("episodes", 2), ("validation_episodes", 1), ("workers", 1)):  # an interval needs 2 episodes
        if getattr(args, name) < lo:
            ap.error(f"--{name.replace('_', '-')} must be >= {lo}, got {getattr(args, name)}")
    if not all(np.isfinite(b) and b > 0 for b in args.B):
        ap.error(f"--B must be finite and > 0 Hz, got {args.B}")
    try:  # every path checked before the computation
        distributed.initialize(args)
        if args.json and Path(args.json).is_dir():
            raise ValueError(f"--json {args.json} is a folder, not a file")
        if args.json:
            check_writable_folder(Path(args.json).parent, "the folder of --json")
        params = make_params(load_curves(args.curves), B=args.B[0])
        for b in args.B:
            check_bandwidth(params, b)
    except (ValueError, OSError, distributed.DistributedError) as e:
        ap.error(str(e))
    r = report(params, tuple(args.B), args.episodes, args.validation_episodes, args.workers)
    if not distributed.is_main():  # process 0 alone reports and writes
        return
    print(markdown(r))
    if args.json:
        atomic_write(args.json, json.dumps(r, indent=2).encode())


if __name__ == "__main__":
    main()
