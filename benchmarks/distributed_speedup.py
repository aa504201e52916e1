"""Wall time of one ``semuav-sweep`` grid on 1 process and on 2 local processes (jax.distributed
over 127.0.0.1, 1 CPU device each), and on 1 process with 2 host devices for comparison.

    python benchmarks/distributed_speedup.py [--episodes 512] [--seeds 2]

The grid: greedy and TSP x B in {5, 25} kHz x the seeds, ``--episodes`` episodes per item. Every
run writes the same item files (checked here). Prints a table and writes
``benchmarks/distributed_speedup.json``.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from multiprocess import environment, start, wait_all  # noqa: E402 - tests/ on the path first

from semuav_jax.io import atomic_write  # noqa: E402


def items(out: Path) -> dict:
    return {p.name: p.read_bytes() for p in sorted((out / "items").glob("*.json"))}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--episodes", type=int, default=512)
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--out", default=str(Path(__file__).with_suffix(".json")))
    args = ap.parse_args()
    grid = {
        "episodes": args.episodes,
        "seeds": list(range(args.seeds)),
        "policies": ["greedy", "tsp"],
        "params": {"B": [5e3, 25e3]},
    }
    rows = []
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        (d / "grid.json").write_text(json.dumps(grid))
        cmd = ["-m", "semuav_jax.cli.sweep", str(d / "grid.json"), "--out"]
        for label, processes, devices in (
            ("1 process, 1 device", 1, 1),
            ("1 process, 2 devices", 1, 2),
            ("2 processes, 1 device each", 2, 1),
        ):
            out = d / label.replace(" ", "_").replace(",", "")
            t0 = time.perf_counter()
            if processes == 1:
                p = subprocess.run(
                    [sys.executable, *cmd, str(out)],
                    cwd=ROOT,
                    env=environment(devices),
                    capture_output=True,
                    text=True,
                    check=False,
                )
                codes = [p.returncode]
            else:
                codes = wait_all(start([*cmd, str(out)], processes, timeout_s=60, devices=devices), 3600)
            wall = time.perf_counter() - t0
            assert codes == [0] * processes, f"{label}: exit codes {codes}"
            rows.append(
                {
                    "run": label,
                    "processes": processes,
                    "devices": processes * devices,
                    "wall_s": wall,
                    "same_items_as_first": items(out) == items(d / rows[0]["run"].replace(" ", "_").replace(",", ""))
                    if rows
                    else True,
                }
            )
    base = rows[0]["wall_s"]
    print(f"{'run':<28} {'wall s':>8} {'speed-up':>9} {'same items':>11}")
    for r in rows:
        r["speedup"] = base / r["wall_s"]
        print(f"{r['run']:<28} {r['wall_s']:>8.1f} {r['speedup']:>9.2f} {r['same_items_as_first']!s:>11}")
    n_items = len(grid["params"]["B"]) * len(grid["policies"]) * args.seeds
    print(f"{n_items} items of {args.episodes} episodes; os.cpu_count() = {os.cpu_count()}")
    atomic_write(args.out, json.dumps({"grid": grid, "cpu_count": os.cpu_count(), "rows": rows}, indent=2).encode())


if __name__ == "__main__":
    main()
