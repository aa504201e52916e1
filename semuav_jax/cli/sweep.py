"""``semuav-sweep GRID.toml`` (or .json): run a grid of parameter overrides x policies x seeds as
resumable items (``semuav_jax.experiments.sweep``, docs/scaling.md) and merge them into a table.

With no option it runs every item not done yet, then merges; ``--item I`` runs item I only (a
Slurm array task or any scheduler's job); ``--merge`` only merges (every item must be done);
``--count`` prints the number of items. Item files go to ``OUT/items``; the table to
``OUT/sweep.csv`` and ``OUT/sweep.json`` (mean PSNR with t intervals, arrival with Wilson intervals).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from semuav_jax import distributed


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("grid", help="grid file (.toml or .json)")
    p.add_argument("--out", default="sweep", help="output folder (default: %(default)s)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--item", type=int, default=None, help="run this item only (0 .. count-1)")
    g.add_argument("--merge", action="store_true", help="only merge the items (all done) into the table")
    g.add_argument("--count", action="store_true", help="print the number of items and exit")
    distributed.add_options(p)
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    return distributed.guarded(_main, argv)


def _main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    name = Path(sys.argv[0]).name
    from semuav_jax.experiments import sweep
    from semuav_jax.io import atomic_write, check_writable_folder

    try:
        grid = sweep.load_grid(args.grid)
        its = sweep.items(grid)
        if args.item is not None and not 0 <= args.item < len(its):
            raise ValueError(f"--item must be in 0 .. {len(its) - 1}, got {args.item}")
        check_writable_folder(args.out)
        distributed.initialize(args)
    except (ValueError, OSError, distributed.DistributedError) as e:
        print(f"{name}: error: {e}", file=sys.stderr)
        return 2
    if args.count:
        print(len(its))
        return 0
    from tqdm import tqdm

    from semuav_jax.sharding import agree

    main_process = distributed.is_main()
    todo = [] if args.merge else [its[args.item]] if args.item is not None else its
    todo = [it for it in todo if not agree(sweep.item_path(args.out, it).is_file())]
    t0 = time.time()
    try:
        for it in tqdm(todo, desc="sweep items", unit="item", dynamic_ncols=True, disable=not main_process):
            metrics = sweep.run_item(grid, it)
            if main_process:
                sweep.save_item(args.out, it, metrics)
        if args.item is not None:
            if main_process:
                print(
                    f"item {args.item} ({its[args.item]['hash']}) in {sweep.item_path(args.out, its[args.item])}"
                    + (" (done before)" if not todo else f" in {time.time() - t0:.1f} s")
                )
            return 0
        if not main_process:  # process 0 alone saved the items: it merges them
            return 0
        table = sweep.merge(args.out, its)
    except ValueError as e:
        if distributed.active():  # a lost peer's collective raises ValueError too: guarded ends the run (exit 1)
            raise
        print(f"{name}: error: {e}", file=sys.stderr)
        return 2
    out = Path(args.out)
    atomic_write(out / "sweep.json", json.dumps(table, indent=1).encode())
    atomic_write(out / "sweep.csv", sweep.table_csv(table).encode())
    print(f"{len(todo)} of {len(its)} items run in {time.time() - t0:.1f} s; wrote {out}/sweep.csv and sweep.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
