"""Train the BS's DDQN from scratch (docs/ddqn.md): ``python train.py`` trains the default agent
(3 seeds vmapped in one program) and compares every seed with the tuned baselines and the planner
on 1000 test layouts at B = 5, 20, 25, 40 kHz; ``--preset paper`` trains the paper's configuration.

The training itself is one compiled program per segment (``semuav_jax.agents.ddqn``); this
script splits it into host-level segments for progress, checkpoints and resume, and writes the
run folder (``semuav_jax.agents.runs``).
"""

from __future__ import annotations

import argparse
import csv
import io
import sys
import time
from pathlib import Path

from semuav_jax import distributed
from semuav_jax.agents.runs import (
    CKPT_FILE,
    CONFIG_FILE,
    CURVE_FILE,
    EVAL_FILE,
    EVAL_MD,
    METRICS_FILE,
    MODEL_FILE,
    ddqn_config,
)
from semuav_jax.cli import interruptible
from semuav_jax.cli.train_folder import (
    INT_COLUMNS,
    NONE,
    RUN_OPTIONS,
    SCENARIO,
    UsageError,
    check_run,
    prepare_folder,
    read_metrics,
    saved_config,
)
from semuav_jax.runfolder import RunFolder

METRIC_COLUMNS = (
    "seed",
    "chunk",
    "env_steps",
    "epsilon",
    "episodes",
    "loss",
    "mean_psnr",
    "return",
    "arrived",
    "coverage",
    "shield_share",
)


def _option_type(default):
    """argparse type and nargs of a config field from its default value."""
    if isinstance(default, bool):
        return {"type": _boolean}
    if isinstance(default, tuple):
        return {"type": _none_or(type(default[0])), "nargs": "+"}
    if default is None or isinstance(default, float):
        return {"type": _none_or(float)}
    return {"type": type(default)}


def _boolean(text: str) -> bool:
    if text.lower() not in ("true", "false"):
        raise ValueError(text)
    return text.lower() == "true"


def _none_or(kind):
    def parse(text: str):
        return NONE if text.lower() == NONE else kind(text)

    parse.__name__ = kind.__name__
    return parse


def parse_args(argv=None):
    import dataclasses

    from semuav_jax.agents.ddqn import PRESETS, DDQNConfig

    p = argparse.ArgumentParser(
        description="Train the BS's DDQN from scratch (docs/ddqn.md). Unset options come "
        "from --preset; on --resume, from the run folder."
    )
    p.add_argument(
        "--preset",
        choices=sorted(PRESETS),
        default="default",
        help="default: waypoint actions, one agent for every bandwidth; paper: the paper's configuration",
    )
    p.add_argument(
        "--scenario",
        choices=("fixed", "random"),
        default=None,
        help=f"fixed paper layout or a new random layout per episode (default: {SCENARIO['scenario']})",
    )
    p.add_argument(
        "--reward-mode",
        choices=("paper", "gain"),
        default=None,
        help=f"reward of MODEL.md section 4 (default: {SCENARIO['reward_mode']}; paper preset: paper)",
    )
    p.add_argument(
        "--bandwidth",
        type=float,
        default=None,
        help=f"B in Hz when bandwidth_range is none, and for --eval-episodes of such an agent (default: {SCENARIO['bandwidth']:g})",
    )
    p.add_argument(
        "--kappa-c",
        type=float,
        default=None,
        help=f"weight of the PSNR gain in the 'gain' reward (default: {SCENARIO['kappa_c']:g})",
    )
    p.add_argument(
        "--r-g",
        type=float,
        default=None,
        help="arrival reward of eq. 4.4 (default: 0, since the shield guarantees arrival and a discounted "
        "bonus only pays for arriving early, docs/ddqn.md; paper preset: 500)",
    )
    d = DDQNConfig()
    for f in dataclasses.fields(DDQNConfig):
        default = getattr(d, f.name)
        shown = (
            "none"
            if default is None
            else " ".join(
                f"{x:g}" if isinstance(x, float) else str(x)
                for x in (default if isinstance(default, tuple) else (default,))
            )
        )
        p.add_argument(
            "--" + f.name.replace("_", "-"),
            default=None,
            help=f"{f.metadata['help']} (default: {shown})",
            **_option_type(default),
        )
    for name, (default, text) in RUN_OPTIONS.items():
        p.add_argument("--" + name, type=type(default), default=None, help=f"{text} (default: {default})")
    p.add_argument(
        "--max-segments",
        type=int,
        default=None,
        help="stop after this many segments in this session (continue later with --resume)",
    )
    p.add_argument(
        "--eval-episodes",
        type=int,
        default=1000,
        help="test layouts for the comparison with the tuned baselines and the planner (0: skip)",
    )
    p.add_argument(
        "--validation-episodes",
        type=int,
        default=500,
        help="validation layouts that choose the baselines' tuned speed v_b* (default: %(default)s)",
    )
    p.add_argument("--workers", type=int, default=2, help="processes for OR-Tools and the planner in the evaluation")
    p.add_argument(
        "--curves",
        type=str,
        default=None,
        help="PSNR curves .npz, or 'synthetic' for the stand-in test curves (default: the shipped DeepJSCC curves)",
    )
    p.add_argument("--out", type=str, default=None, help="run folder (default: runs/ddqn_<preset>)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--resume", action="store_true", help="continue the run in --out from its checkpoint")
    g.add_argument("--overwrite", action="store_true", help="delete the contents of an existing --out first")
    distributed.add_options(p)
    args = p.parse_args(argv)
    args.command = " ".join(["python train.py", *(sys.argv[1:] if argv is None else argv)])
    if args.out is None:
        args.out = f"runs/ddqn_{args.preset}"
    for name in ("seeds", "segments", "max_segments", "workers", "validation_episodes"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            raise UsageError(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
    if args.eval_episodes < 0 or args.eval_episodes == 1:
        raise UsageError(
            f"--eval-episodes must be 0 (no comparison) or >= 2 (its intervals need two), got {args.eval_episodes}"
        )
    return args


def run_config(args) -> dict:
    """The JSON-able description of a run (written to config.json; read back on --resume)."""
    import dataclasses

    from semuav_jax.agents.ddqn import PRESETS, DDQNConfig, preset_config

    preset = PRESETS[args.preset]
    names = {f.name for f in dataclasses.fields(DDQNConfig)}
    given = {k: getattr(args, k) for k in names if getattr(args, k) is not None}
    for k, v in given.items():
        if isinstance(v, list) and NONE in v and len(v) > 1:
            raise UsageError(f"--{k.replace('_', '-')}: give either none or numbers, got {' '.join(map(str, v))}")
    given = {k: None if v == NONE or v == [NONE] else tuple(v) if isinstance(v, list) else v for k, v in given.items()}
    cfg = preset_config(args.preset, **given)
    scenario = {k: getattr(args, k) if getattr(args, k) is not None else preset.get(k, v) for k, v in SCENARIO.items()}
    run = {k: getattr(args, k) if getattr(args, k) is not None else v for k, (v, _) in RUN_OPTIONS.items()}
    return {
        "preset": args.preset,
        **scenario,
        **run,
        "curves": args.curves,
        "command": args.command,
        "ddqn": cfg.to_dict(),
    }


def load_run_config(args) -> dict:
    """The run's config: read back from the run folder on --resume, else built from the options."""
    if args.resume:
        return saved_config(args)
    cfg = run_config(args)
    check_run(cfg, "")
    return cfg


def plot_curves(rows, path: Path, reference: dict | None = None) -> None:
    import matplotlib.pyplot as plt

    from semuav_jax.io import save_figure

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for seed in sorted({r["seed"] for r in rows}):
        rs = [r for r in rows if r["seed"] == seed]
        x = [r["env_steps"] for r in rs]
        axes[0].plot(x, [r["mean_psnr"] for r in rs], label=f"seed {seed}")
        axes[1].plot(x, [r["return"] for r in rs])
    for name, value in (reference or {}).items():
        axes[0].axhline(value, ls="--", color="gray")
        axes[0].annotate(name, (0, value), fontsize=8, color="gray")
    axes[0].set(
        xlabel="environment steps",
        ylabel="mean PSNR of finished episodes (dB)",
        title="training (ε-greedy, over the training bandwidths)",
    )
    axes[1].set(xlabel="environment steps", ylabel="episode return")
    axes[0].legend(fontsize=8)
    save_figure(fig, path, dpi=110)


def segment_lengths(num_chunks: int, segments: int, done: int):
    """Chunks per remaining segment: equal lengths (one compilation) plus at most one remainder."""
    seg = -(-num_chunks // segments)
    left = num_chunks - done
    return [seg] * (left // seg) + ([left % seg] if left % seg else [])


def main(argv=None) -> int:
    return interruptible(
        lambda a: distributed.guarded(_main, a),
        argv,
        "the run folder is consistent: continue with "
        "--resume (before its first checkpoint, --resume or the same command starts it again)",
    )


def _main(argv=None) -> int:
    try:
        args = parse_args(argv)
        distributed.initialize(args)
        cfg = load_run_config(args)
    except (UsageError, ValueError, distributed.DistributedError) as e:
        print(f"{Path(sys.argv[0]).name}: error: {e}", file=sys.stderr)
        return 2

    from semuav_jax.agents.runs import run_params

    out = Path(args.out)
    try:
        params = run_params(cfg)
        config = ddqn_config(cfg, out / CONFIG_FILE)
        if distributed.is_main():  # of several processes, process 0 writes the run folder
            folder = prepare_folder(args, cfg)
            distributed.barrier("run folder claimed")
        else:
            distributed.barrier("run folder claimed")
            folder = RunFolder.view(args.out)
    except (UsageError, ValueError, FileNotFoundError) as e:
        print(f"{Path(sys.argv[0]).name}: error: {e}", file=sys.stderr)
        return 2
    try:
        return _train(args, cfg, params, config, folder)
    finally:
        folder.release()


def _train(args, cfg, params, config, folder) -> int:
    import jax
    import numpy as np
    from flax import serialization
    from tqdm import tqdm

    from semuav_jax.agents.ddqn import make_train

    out = folder.path
    bar = None

    def progress(chunk):  # from inside the compiled segment, once per seed and chunk
        if bar is not None and int(chunk) > bar.n:
            bar.update(int(chunk) - bar.n)

    trainer = make_train(config, params, progress=progress)
    keys = jax.random.split(jax.random.PRNGKey(cfg["seed"]), cfg["seeds"])
    init = jax.jit(jax.vmap(trainer.init))
    template = jax.eval_shape(init, keys)
    state, rows = None, []
    if args.resume and not (out / CKPT_FILE).is_file():  # stopped before its first checkpoint
        print(f"{out} has no checkpoint yet: starting its run from chunk 0")
    elif args.resume:
        try:
            state = serialization.from_bytes(template, (out / CKPT_FILE).read_bytes())
            if jax.tree.structure(state) != jax.tree.structure(template) or any(
                np.shape(a) != b.shape for a, b in zip(jax.tree.leaves(state), jax.tree.leaves(template))
            ):
                raise ValueError("its arrays do not match config.json")
            rows = read_metrics(out, int(np.asarray(state.chunk)[0]))
        except Exception as e:  # noqa: BLE001 - flax raises any kind for a file that is not this checkpoint
            text = (
                e
                if isinstance(e, UsageError)
                else f"--resume: {out / CKPT_FILE} is unreadable or not this run's checkpoint ({e})"
            )
            print(f"{Path(sys.argv[0]).name}: error: {text}", file=sys.stderr)
            return 2
        print(f"resuming {out} at chunk {int(np.asarray(state.chunk)[0])} / {config.num_chunks}")

    t0 = time.time()
    if state is None:
        state = init(keys)
    done = int(np.asarray(state.chunk)[0])
    runs = {}
    bar = tqdm(total=config.num_chunks, initial=done, unit="chunk", desc="training", dynamic_ncols=True)
    for n in segment_lengths(config.num_chunks, cfg["segments"], done)[: args.max_segments]:
        if n not in runs:
            runs[n] = jax.jit(jax.vmap(lambda s, n=n: trainer.run(s, n)))
        state, metrics = runs[n](state)
        metrics = jax.tree.map(np.asarray, metrics)
        if not np.isfinite(metrics["loss"]).all() or not all(
            np.isfinite(w).all() for w in jax.tree.leaves(state.params)
        ):
            bar.close()
            kept = f"keeps its checkpoint at chunk {done}" if (out / CKPT_FILE).is_file() else "has no checkpoint"
            print(
                f"{Path(sys.argv[0]).name}: error: training diverged (non-finite loss or weights) in chunks "
                f"{done + 1}..{done + n}; {out} {kept} and no model: start again with other options (e.g. a smaller "
                "--lr) and --overwrite",
                file=sys.stderr,
            )
            return 2
        for s in range(cfg["seeds"]):
            for c in range(n):
                rows.append(
                    {
                        "seed": s,
                        "chunk": done + c + 1,
                        **{
                            k: int(metrics[k][s, c]) if k in INT_COLUMNS else float(metrics[k][s, c])
                            for k in METRIC_COLUMNS[2:]
                        },
                    }
                )
        done += n
        if not distributed.is_main():
            continue
        text = io.StringIO()
        w = csv.DictWriter(text, METRIC_COLUMNS)
        w.writeheader()
        w.writerows({k: r[k] for k in METRIC_COLUMNS} for r in rows)
        folder.write(METRICS_FILE, text.getvalue().encode())  # before the checkpoint: see resume
        folder.write(CKPT_FILE, serialization.to_bytes(state))
        plot_curves(rows, folder.record(CURVE_FILE))
        bar.set_postfix(psnr=f"{metrics['mean_psnr'][:, -1].mean():.2f}", eps=f"{metrics['epsilon'][0, -1]:.2f}")
        bar.update(done - bar.n)  # the callbacks moved it within the segment
    bar.close()
    if done < config.num_chunks:
        print(f"stopped at chunk {done} / {config.num_chunks}; continue with --resume --out {out}")
        return 0
    wall = time.time() - t0
    folder.write(MODEL_FILE, serialization.to_bytes(state.params))  # process 0 alone writes (a view elsewhere)
    distributed.barrier("weights written")  # the evaluation below and eval.py read them in every process
    print(
        f"training: {config.num_chunks * config.steps_per_chunk * config.num_envs * cfg['seeds']:,} env steps "
        f"in {wall:.0f} s (this session)"
    )

    if args.eval_episodes:
        from semuav_jax.experiments.learned import evaluate_run, markdown

        folder.record(EVAL_FILE), folder.record(EVAL_MD)
        report = evaluate_run(
            out,
            args.eval_episodes,
            args.validation_episodes,
            args.workers,
            log=tqdm.write,
            extra={"train_wall_s": wall},
        )
        if not distributed.is_main():
            return 0
        print(markdown(report))
        if config.bandwidth_range is None:  # one bandwidth: its references are comparable with the curve
            ref = {k: v["mean_psnr"] for k, v in report["rows"][-1]["references"].items()}
            plot_curves(rows, out / CURVE_FILE, ref)
    print(f"run folder: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
