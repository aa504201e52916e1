"""Figures of Fig. 2 (a, b, c) and the training curves, written atomically as PNG (docs/RESULTS.md)."""

from __future__ import annotations

import io
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from semuav_jax.stats import wilson_interval  # noqa: E402
from semuav_jax.io import atomic_write  # noqa: E402

STYLE = {"DDQN": dict(color="C3", marker="o"), "greedy": dict(color="C0", marker="s"), "tsp": dict(color="C2", marker="^")}
LABEL = {"DDQN": "DDQN", "greedy": "Greedy", "tsp": "TSP"}


def save_figure(fig, path: Path, dpi: int = 120):
    """Write ``fig`` as a PNG atomically and close it."""
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    atomic_write(path, buf.getvalue())


def _panel(rows, panel, x_key, x_scale, xlabel, title, path, hline_ddqn=False):
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for policy in ("DDQN", "greedy", "tsp"):
        rs = sorted((r for r in rows if r["panel"] == panel and r["policy"] == policy), key=lambda r: r[x_key] or 0)
        if not rs:
            continue
        for ax, metric in zip(axes, ("mean_psnr", "coverage", "arrived")):
            y = np.array([r[metric] for r in rs])
            if metric == "arrived":
                lo, hi = wilson_interval(y, np.array([r["episodes"] for r in rs]))
            else:
                e = np.array([r[f"{metric}_ci95"] for r in rs])
                lo, hi = y - e, y + e
            if hline_ddqn and policy == "DDQN":
                ax.axhline(y[0], color=STYLE[policy]["color"], label=f"{LABEL[policy]} (no speed parameter)")
                ax.axhspan(lo[0], hi[0], color=STYLE[policy]["color"], alpha=0.15)
                continue
            x = np.array([r[x_key] for r in rs]) * x_scale
            ax.errorbar(x, y, yerr=np.stack([y - lo, hi - y]), capsize=3, label=LABEL[policy], **STYLE[policy])
    n = rows[0]["episodes"]
    for ax, ylabel in zip(axes, ("mean PSNR (dB)", "devices covered (of N)", "arrival rate")):
        ax.set(xlabel=xlabel, ylabel=ylabel)
        ax.grid(alpha=0.3)
    axes[0].set_title(title)
    axes[1].set_title(f"error bars: 95 % CI over {n} layouts (arrival: Wilson)")
    axes[0].legend()
    save_figure(fig, path)


def fig2a(rows, path):
    _panel(rows, "a", "bandwidth_hz", 1e-3, "device bandwidth B (kHz)", "(a) baselines at 8.9 m/s", path)


def fig2b(rows, path, bandwidth):
    _panel(rows, "b", "v_b", 1.0, "baseline speed v_b (m/s)", f"(b) B = {bandwidth / 1e3:g} kHz", path,
           hline_ddqn=True)


def fig2c(traj: dict, params, path):
    """Trajectories on the paper layout: devices with their coverage disc, BS, start and destination."""
    fig, ax = plt.subplots(figsize=(9, 5.8))
    radius = float(np.sqrt(float(params.D_com) ** 2 - float(params.H) ** 2))
    for i, p in enumerate(np.asarray(params.device_pos)):
        ax.add_patch(plt.Circle(p, radius, color="0.8", zorder=0))
        ax.annotate(str(i), p, ha="center", va="center", fontsize=8)
    ax.plot(*np.asarray(params.bs_pos), "k^", ms=10, label="BS")
    ax.plot(*np.asarray(params.q0), "ko", ms=7, label="start q0")
    ax.add_patch(plt.Circle(np.asarray(params.q_fin), float(params.r_arr), color="k", fill=False))
    ax.plot(*np.asarray(params.q_fin), "k*", ms=12, label="destination")
    for name, t in traj.items():
        ax.plot(t["q"][:, 0], t["q"][:, 1], color=STYLE[name]["color"], lw=1.6,
                label=f"{LABEL[name]}: {t['mean_psnr']:.1f} dB, {t['coverage']:.0f} covered, {t['mission_time']:.0f} s")
    # the UAV may leave the area (no wall, docs/model.md eq. 3.3): the view holds the area and every path
    pts = np.concatenate([np.array([[0.0, 0.0], [float(params.Lx), float(params.Ly)]])] + [t["q"] for t in traj.values()])
    lo, hi = pts.min(0) - 10.0, pts.max(0) + 10.0
    ax.add_patch(plt.Rectangle((0, 0), float(params.Lx), float(params.Ly), fill=False, ls=":", color="0.5"))
    ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), xlabel="x (m)", ylabel="y (m)", aspect="equal",
           title=f"(c) trajectories on the paper layout, B = {float(params.B) / 1e3:g} kHz "
                 f"(grey: {radius:.0f} m coverage discs)")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    save_figure(fig, path)


def training_curves(agents, path):
    """Mean PSNR of finished training episodes (epsilon-greedy) per chunk, one line per bandwidth."""
    c = agents.curves
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    for i, b in enumerate(agents.bandwidths):
        axes[0].plot(c["env_steps"][i], c["mean_psnr"][i], label=f"B = {b / 1e3:g} kHz")
        axes[1].plot(c["env_steps"][i], c["return"][i])
    axes[0].set(xlabel="environment steps", ylabel="mean PSNR of finished episodes (dB)", title="DDQN training")
    axes[1].set(xlabel="environment steps", ylabel="episode return")
    axes[0].legend(fontsize=8)
    save_figure(fig, path)
