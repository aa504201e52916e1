"""train.py's loop (docs/ddqn.md): the compiled training program split into host-level segments for
progress, checkpoints (``semuav_jax.checkpoint``) and resume; metrics.csv and the learning curve
after each segment; the weights and the comparison with the references at the end."""

from __future__ import annotations

import csv
import io
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from semuav_jax import checkpoint, distributed
from semuav_jax.agents.runs import CKPT_FILE, CURVE_FILE, EVAL_FILE, EVAL_MD, METRICS_FILE, MODEL_FILE
from semuav_jax.cli import stop_if_asked
from semuav_jax.cli.train_folder import INT_COLUMNS, UsageError, read_metrics

if TYPE_CHECKING:
    from jax.typing import ArrayLike

    from semuav_jax.agents.run_config import RunConfig
    from semuav_jax.runfolder import RunFolder

METRIC_COLUMNS = ("seed", "chunk", "env_steps", "epsilon", "episodes", "loss", "mean_psnr", "return", "arrived",
                  "coverage", "shield_share")  # fmt: skip


def plot_curves(rows: list[dict], path: Path, reference: dict | None = None) -> None:
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
    axes[0].set(xlabel="environment steps", ylabel="mean PSNR of finished episodes (dB)",
                title="training (ε-greedy, over the training bandwidths)")  # fmt: skip
    axes[1].set(xlabel="environment steps", ylabel="episode return")
    axes[0].legend(fontsize=8)
    save_figure(fig, path, dpi=110)


def segment_lengths(num_chunks: int, segments: int, done: int) -> list[int]:
    """Chunks per remaining segment: equal lengths (one compilation) plus at most one remainder."""
    seg = -(-num_chunks // segments)
    left = num_chunks - done
    return [seg] * (left // seg) + ([left % seg] if left % seg else [])


def _error(text: str) -> int:
    print(f"{Path(sys.argv[0]).name}: error: {text}", file=sys.stderr)
    return 2


def _csv(rows: list[dict]) -> bytes:
    text = io.StringIO()
    w = csv.DictWriter(text, METRIC_COLUMNS)
    w.writeheader()
    w.writerows({k: r[k] for k in METRIC_COLUMNS} for r in rows)
    return text.getvalue().encode()


def train_run(cfg: RunConfig, folder: RunFolder, resume: bool, max_segments: int | None) -> int:
    """Train the run ``cfg`` (a ``RunConfig``) into ``folder`` (claimed), from its checkpoint on
    ``resume``, for at most ``max_segments`` segments; then evaluate it (``cfg.eval_episodes``)."""
    import jax
    import numpy as np
    from tqdm import tqdm

    from semuav_jax.agents.trainer import make_train

    out, config = folder.path, cfg.agent
    bar = None

    def progress(chunk: ArrayLike) -> None:  # from inside the compiled segment, once per seed and chunk
        if bar is not None and int(chunk) > bar.n:
            bar.update(int(chunk) - bar.n)

    trainer = make_train(config, cfg.env_params(), progress=progress)
    keys = jax.random.split(jax.random.PRNGKey(cfg.seed), cfg.seeds)
    init = jax.jit(jax.vmap(trainer.init))
    state, rows = None, []
    if resume and not (out / CKPT_FILE).is_file():  # stopped before its first checkpoint
        print(f"{out} has no checkpoint yet: starting its run from chunk 0")
    elif resume:
        try:
            state, _ = checkpoint.restore(out / CKPT_FILE, jax.eval_shape(init, keys))
            rows = read_metrics(out, int(np.asarray(state.chunk)[0]))
        except (UsageError, ValueError) as e:
            return _error(f"--resume: {e}")
        print(f"resuming {out} at chunk {int(np.asarray(state.chunk)[0])} / {config.num_chunks}")

    t0 = time.time()
    state = init(keys) if state is None else state
    done = int(np.asarray(state.chunk)[0])
    runs = {}
    bar = tqdm(total=config.num_chunks, initial=done, unit="chunk", desc="training", dynamic_ncols=True)
    for n in segment_lengths(config.num_chunks, cfg.segments, done)[:max_segments]:
        stop_if_asked()
        if n not in runs:
            runs[n] = jax.jit(jax.vmap(lambda s, n=n: trainer.run(s, n)))
        state, metrics = runs[n](state)
        metrics = jax.tree.map(np.asarray, metrics)
        weights = jax.tree.leaves(state.params)
        if not np.isfinite(metrics["loss"]).all() or not all(np.isfinite(w).all() for w in weights):
            bar.close()
            kept = f"keeps its checkpoint at chunk {done}" if (out / CKPT_FILE).is_file() else "has no checkpoint"
            return _error(
                f"training diverged (non-finite loss or weights) in chunks {done + 1}..{done + n}; {out} {kept} "
                "and no model: start again with other options (e.g. a smaller --lr) and --overwrite"
            )
        for s in range(cfg.seeds):
            for c in range(n):
                values = {k: metrics[k][s, c] for k in METRIC_COLUMNS[2:]}
                values = {k: int(v) if k in INT_COLUMNS else float(v) for k, v in values.items()}
                rows.append({"seed": s, "chunk": done + c + 1, **values})
        done += n
        if not distributed.is_main():
            continue
        folder.write(METRICS_FILE, _csv(rows))  # before the checkpoint: see resume
        checkpoint.save(folder.record(CKPT_FILE), state)
        plot_curves(rows, folder.record(CURVE_FILE))
        bar.set_postfix(psnr=f"{metrics['mean_psnr'][:, -1].mean():.2f}", eps=f"{metrics['epsilon'][0, -1]:.2f}")
        bar.update(done - bar.n)  # the callbacks moved it within the segment
    bar.close()
    if done < config.num_chunks:
        print(f"stopped at chunk {done} / {config.num_chunks}; continue with --resume --out {out}")
        return 0
    stop_if_asked()
    wall = time.time() - t0
    if distributed.is_main():  # process 0 alone writes
        checkpoint.save(folder.record(MODEL_FILE), state.params)
    distributed.barrier("weights written")  # the evaluation below and eval.py read them in every process
    steps = config.num_chunks * config.steps_per_chunk * config.num_envs * cfg.seeds
    print(f"training: {steps:,} env steps in {wall:.0f} s (this session)")
    if cfg.eval_episodes:
        from semuav_jax.experiments.learned import evaluate_run, markdown

        folder.record(EVAL_FILE), folder.record(EVAL_MD)
        report = evaluate_run(out, log=tqdm.write, extra={"train_wall_s": wall})
        if not distributed.is_main():
            return 0
        print(markdown(report))
        if config.bandwidth_range is None:  # one bandwidth: its references are comparable with the curve
            ref = {k: v["mean_psnr"] for k, v in report["rows"][-1]["references"].items()}
            plot_curves(rows, out / CURVE_FILE, ref)
    print(f"run folder: {out}")
    return 0
