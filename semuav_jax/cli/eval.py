"""Reproduce the paper's Fig. 2 into ``results/`` (docs/RESULTS.md).

``python eval.py --quick``: the shipped agent (the output of ``python train.py``, docs/ddqn.md)
against greedy and TSP at 8.9 m/s and at their tuned speed, greedy-dwell and TSP-dwell at their
tuned knobs, dwell-switch, the open-loop and the exact planner and plan-switch
(docs/baselines.md), at 4 bandwidths and 4 speeds on 300 test layouts. ``python eval.py``: trains
that agent from scratch first (``train.py``'s default, in OUT/agent, resumed if interrupted), then
8 bandwidths and 8 speeds on 1000 test layouts. ``--agent RUN`` takes a finished ``train.py`` run folder instead.
Writes fig2a/b/c.png and fig2.json (every number, and the speeds and dwell times behind them).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from semuav_jax import distributed
from semuav_jax.cli import interruptible

if TYPE_CHECKING:
    from semuav_jax.curves import PSNRCurves
    from semuav_jax.runfolder import RunFolder

OUT_FILES = ("fig2.json", "fig2.md", "fig2a.png", "fig2b.png", "fig2c.png")  # what eval.py writes in --out


class UsageError(Exception):
    """A bad option or folder: one line on stderr, exit code 2."""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    from semuav_jax.experiments.fig2 import FULL, QUICK, check_bandwidths

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="the shipped agent, a smaller grid (docs/RESULTS.md)")
    p.add_argument("--agent", default=None, help="a finished train.py run folder to evaluate (no training)")
    p.add_argument("--out", default="results", help="output folder (default: %(default)s)")
    p.add_argument("--overwrite", action="store_true", help="replace the results in an existing --out")
    p.add_argument(
        "--layouts",
        type=int,
        default=None,
        help=f"test layouts per point (default: {FULL['layouts']}; --quick: {QUICK['layouts']})",
    )
    p.add_argument(
        "--validation-layouts",
        type=int,
        default=None,
        help=f"layouts that choose v_b* (default: {FULL['validation_layouts']}; "
        f"--quick: {QUICK['validation_layouts']})",
    )
    p.add_argument("--bandwidths", type=float, nargs="+", default=None, help=f"Hz (default: {FULL['bandwidths']})")
    p.add_argument("--velocities", type=float, nargs="+", default=None, help=f"m/s (default: {FULL['velocities']})")
    p.add_argument("--workers", type=int, default=2, help="processes for OR-Tools and the planner")
    p.add_argument("--curves", default=None, help="PSNR curves .npz (default: the shipped DeepJSCC curves)")
    p.add_argument(
        "--animate",
        metavar="GIF",
        default=None,
        help="only write an animated GIF: the agent (--agent, else the shipped one) and the references "
        "flying the paper layout at 25 kHz side by side",
    )
    distributed.add_options(p)
    a = p.parse_args(argv)
    base = QUICK if a.quick else FULL
    pick = lambda name: base[name] if getattr(a, name) is None else getattr(a, name)  # 0 is refused, not a default
    a.grid = {
        "bandwidths": tuple(pick("bandwidths")),
        "velocities": tuple(pick("velocities")),
        "layouts": pick("layouts"),
        "validation_layouts": pick("validation_layouts"),
    }
    if a.grid["layouts"] < 2 or a.grid["validation_layouts"] < 1 or a.workers < 1:
        raise UsageError("--layouts must be >= 2, --validation-layouts and --workers >= 1")
    for name, xs in (("bandwidths", a.grid["bandwidths"]), ("velocities", a.grid["velocities"])):
        if not all(x > 0 and x < float("inf") for x in xs):
            raise UsageError(f"--{name} must be finite and > 0, got {xs}")
    try:
        check_bandwidths(a.grid["bandwidths"])
    except ValueError as e:
        raise UsageError(str(e)) from None
    if a.quick and a.agent:
        raise UsageError("--quick evaluates the shipped agent; drop --agent or --quick")
    if a.animate is not None:
        if not a.animate.endswith(".gif"):
            raise UsageError(f"--animate must name a .gif file, got {a.animate!r}")
    return a


def claim_out(args: argparse.Namespace) -> RunFolder:
    """The --out folder claimed (``semuav_jax.runfolder``): ours or new, locked; its results removed
    with --overwrite (its saved steps stay: they are keyed), refused without."""
    from semuav_jax.runfolder import RunFolder

    if not distributed.is_main():  # process 0 claims (a shared folder); the others read its saved steps
        distributed.barrier("results folder claimed")
        return RunFolder.view(args.out)
    folder = RunFolder.claim(args.out, "eval.py results")
    if any(n in folder.files for n in OUT_FILES):
        if not args.overwrite:
            folder.release()
            raise UsageError(f"{args.out} already holds results; pass --overwrite to replace them")
        for n in OUT_FILES:
            folder.remove(n)
    distributed.barrier("results folder claimed")
    return folder


def agent_folder(args: argparse.Namespace, out: Path) -> Path:
    """The run folder of the agent: the shipped one, --agent, or OUT/agent trained (or resumed) here."""
    from semuav_jax.agents.runs import CKPT_FILE, finished, shipped_folder
    from semuav_jax.cli import train
    from semuav_jax.sharding import agree

    if args.quick:
        return shipped_folder()
    if args.agent:
        return Path(args.agent)
    folder = out / "agent"
    if not agree(finished(folder)):  # every process decides alike (a shared folder)
        resume = ["--resume"] if agree((folder / CKPT_FILE).is_file()) else []
        cmd = ["--out", str(folder), "--eval-episodes", "0", *resume] + (
            ["--curves", args.curves] if args.curves else []
        )
        print(
            ("resuming" if resume else "training") + f" the default agent in {folder} (python train.py {' '.join(cmd)})"
        )
        if train.main(cmd) != 0:
            raise UsageError(f"training into {folder} failed")
        distributed.barrier("agent trained")  # process 0 wrote it: the others read it next
    return folder


def main(argv: list[str] | None = None) -> int:
    return interruptible(
        lambda a: distributed.guarded(_main, a), argv, "the same command continues at the step it stopped in"
    )


def _main(argv: list[str] | None = None) -> int:
    try:
        args = parse_args(argv)
        distributed.initialize(args)
    except (UsageError, distributed.DistributedError) as e:
        print(f"{Path(sys.argv[0]).name}: error: {e}", file=sys.stderr)
        return 2
    if args.animate:
        return _animate(args)

    from baselines.report import check_bandwidth
    from semuav_jax.agents.runs import load_run
    from semuav_jax.agents.scenarios import scenario_params
    from semuav_jax.curves import load_curves
    from semuav_jax.io import check_writable_folder

    t0 = time.time()
    try:
        if distributed.is_main():  # the one process that writes: every path checked before any computation
            check_writable_folder(args.out)
        curves = load_curves(args.curves) if args.curves else None
        base = scenario_params("random", curves, reward_mode="gain")
        for b in args.grid["bandwidths"]:
            check_bandwidth(base, b, args.grid["velocities"])
        if args.agent:
            load_run(args.agent)
        results = claim_out(args)
    except (UsageError, ValueError, FileNotFoundError, OSError) as e:
        print(f"{Path(sys.argv[0]).name}: error: {e}", file=sys.stderr)
        return 2
    try:
        return _evaluate(args, results, curves, t0)
    finally:
        results.release()


def _evaluate(args: argparse.Namespace, results: RunFolder, curves: PSNRCurves | None, t0: float) -> int:
    import jax
    from tqdm import tqdm

    from semuav_jax.agents.network import q_network
    from semuav_jax.agents.runs import MODEL_FILE, load_run
    from semuav_jax.experiments import fig2, figures
    from semuav_jax.provenance import file_hash, provenance

    out = results.path
    try:
        folder = agent_folder(args, out)
        run, nets = load_run(folder)  # the agent flies in the env it was trained in (its RunConfig)
        config, params, fixed = run.agent, run.env_params("random", curves), run.env_params("fixed", curves)
    except (UsageError, ValueError, FileNotFoundError, OSError) as e:
        print(f"{Path(sys.argv[0]).name}: error: {e}", file=sys.stderr)
        return 2
    train_s = time.time() - t0
    print(f"agent: {folder} ({jax.tree.leaves(nets)[0].shape[0]} seeds); JAX devices: {jax.device_count()}")
    network = q_network(params, config)
    key = {
        "grid": args.grid,
        "agent": str(folder.resolve()),
        "weights_sha256": file_hash(folder / MODEL_FILE),
        **provenance(params),
    }
    with tqdm(total=fig2.stage_count(args.grid), desc="Fig. 2", unit="step", dynamic_ncols=True) as bar:

        def log(msg: str) -> None:
            bar.write(msg)
            bar.update(1)

        # each step is saved in OUT/stages: an interrupted run continues at the first step not done
        stages = fig2.Stages(results, key, log, note=bar.write)
        r = fig2.run(network, nets, config, params, fixed, args.grid, args.workers, stages=stages)
    r.update(
        agent=str(folder),
        agent_command=run.command,
        train_s=train_s,
        eval_s=time.time() - t0 - train_s,
        devices=jax.device_count(),
        grid={k: list(v) if isinstance(v, tuple) else v for k, v in args.grid.items()},
        **provenance(params),
    )
    r["paths"] = {
        k: {m: (v.tolist() if hasattr(v, "tolist") else v) for m, v in p.items()} for k, p in r["paths"].items()
    }
    if not distributed.is_main():  # process 0 alone writes the results
        return 0
    results.write("fig2.json", json.dumps(r, indent=2).encode())
    md = fig2.markdown(r)
    results.write("fig2.md", (md + "\n").encode())
    figures.fig2a(r, results.record("fig2a.png"))
    figures.fig2b(r, results.record("fig2b.png"))
    figures.fig2c(r["paths"], fixed.replace(B=fig2.PANEL_B), results.record("fig2c.png"))
    print(md)
    print(f"wrote {out}/fig2a.png fig2b.png fig2c.png fig2.json fig2.md in {time.time() - t0:.0f} s")
    return 0


def _animate(args: argparse.Namespace) -> int:
    """--animate GIF: seed 0 of the agent, greedy and TSP at their v_b* (the agent folder's eval.json,
    else tuned here on --validation-layouts) and the planner, one episode each on the paper layout."""
    from baselines.report import tune
    from semuav_jax.agents.network import q_network
    from semuav_jax.agents.runs import load_run, shipped_folder
    from semuav_jax.curves import load_curves
    from semuav_jax.experiments.animation import (
        animate,
        paper_layout_traces,
        shipped_tuned_speeds,
    )
    from semuav_jax.experiments.fig2 import PANEL_B
    from semuav_jax.io import check_writable_folder

    t0 = time.time()
    try:
        check_writable_folder(Path(args.animate).parent, "--animate")
        folder = Path(args.agent) if args.agent else shipped_folder()
        run, nets = load_run(folder)
        curves = load_curves(args.curves) if args.curves else None
        config, fixed = run.agent, run.env_params("fixed", curves).replace(B=PANEL_B)
    except (ValueError, FileNotFoundError, OSError) as e:
        print(f"{Path(sys.argv[0]).name}: error: {e}", file=sys.stderr)
        return 2
    tuned = None if args.curves else shipped_tuned_speeds(folder, PANEL_B)
    if tuned is None:
        print(f"tuning v_b* at {PANEL_B / 1e3:g} kHz on {args.grid['validation_layouts']} validation layouts")
        t = tune(
            run.env_params("random", curves).replace(B=PANEL_B),
            (PANEL_B,),
            args.grid["validation_layouts"],
            workers=args.workers,
            switch=False,
        )
        tuned = {n: t[n]["v_star"][0] for n in ("greedy", "tsp")} | {
            n: tuple(t[n]["knobs"][0]) for n in ("greedy-dwell", "tsp-dwell")
        }
    traces = paper_layout_traces(q_network(fixed, config), nets, config, fixed, tuned)
    animate(traces, fixed, args.animate, progress=True)
    print(f"wrote {args.animate} ({Path(args.animate).stat().st_size / 1e6:.2f} MB) in {time.time() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
