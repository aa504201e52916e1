"""Figures of Fig. 2 (a, b, c) from the results of ``experiments/fig2.py``, written atomically as PNG
(docs/RESULTS.md)."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

from semuav_jax.control import range_radius  # noqa: E402
from semuav_jax.experiments.fig2 import REFERENCES  # noqa: E402
from semuav_jax.io import save_figure  # noqa: E402
from semuav_jax.stats import wilson_interval  # noqa: E402

if TYPE_CHECKING:
    from semuav_jax.params import EnvParams

STYLE = {
    "agent": dict(color="C3", marker="o", label="DDQN (ours, mean of seeds)"),
    "greedy 8.9": dict(color="C0", marker="s", ls=":", mfc="none", label="greedy, 8.9 m/s"),
    "tsp 8.9": dict(color="C2", marker="^", ls=":", mfc="none", label="TSP, 8.9 m/s"),
    "greedy v_b*": dict(color="C0", marker="s", label="greedy, tuned v_b*"),
    "tsp v_b*": dict(color="C2", marker="^", label="TSP, tuned v_b*"),
    "greedy-dwell": dict(color="C1", marker="v", label="greedy-dwell, tuned"),
    "tsp-dwell": dict(color="C8", marker="P", label="TSP-dwell, tuned"),
    "dwell-switch": dict(color="C5", marker="X", label="dwell-switch (search over the dwell rules)"),
    "planner": dict(color="C4", marker="D", ls="--", mfc="none", label="open-loop planner"),
    "exact planner": dict(color="C4", marker="D", label="exact planner (receding horizon)"),
    "plan-switch": dict(color="k", marker="*", ms=9, label="plan-switch (exact planner + dwell rules)"),
}
# panel (b): the policies that set their own speed
BANDS = ("agent", "greedy-dwell", "tsp-dwell", "dwell-switch", "planner", "exact planner", "plan-switch")


def _finish(fig: plt.Figure, ax: plt.Axes, ax2: plt.Axes, path: str | os.PathLike, fontsize: int, ncol: int) -> None:
    """Grids, ``ax``'s legend below the panels (it hides no data whatever the grid), and the file."""
    for a in (ax, ax2):
        a.grid(alpha=0.3)
    fig.legend(
        *ax.get_legend_handles_labels(),
        fontsize=fontsize,
        loc="upper center",
        bbox_to_anchor=(0.5, 0.0),
        ncol=ncol,
        frameon=False,
    )
    save_figure(fig, path)


def fig2a(r: dict, path: str | os.PathLike) -> None:
    """Mean PSNR vs B (left) and devices covered (right): the agent with its t interval across seeds, the
    baselines at 8.9 m/s and at v_b*, the dwell rules, dwell-switch, both planners and plan-switch
    (95 % t intervals over layouts)."""
    rows = r["panel_a"]
    B = np.array([row["B"] for row in rows]) / 1e3
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 4.2), gridspec_kw={"width_ratios": [3, 2]})
    for name, st in STYLE.items():
        if name != "agent" and name not in rows[0]:
            continue  # results written before a reference existed
        if name == "agent":
            y = np.array([row["agent"][0] for row in rows])
            e = np.array([row["agent"][1] for row in rows])
            cov = [row["agent_coverage"] for row in rows]
        else:
            y = np.array([row[name]["mean_psnr"][0] for row in rows])
            e = np.array([row[name]["mean_psnr"][1] for row in rows])
            cov = [row[name]["coverage"] for row in rows]
        ax.errorbar(B, y, yerr=e, capsize=3, **st)
        ax2.plot(B, cov, **{k: v for k, v in st.items() if k != "label"})
    ax.set(
        xlabel="device bandwidth B (kHz)",
        ylabel="mean PSNR over the N devices (dB)",
        title=f"(a) {r['layouts']} test layouts; DDQN: {r['seeds']} seeds, CI across seeds",
    )
    ax2.set(xlabel="device bandwidth B (kHz)", ylabel="devices covered (of N = 10)", title="coverage")
    _finish(fig, ax, ax2, path, fontsize=9, ncol=6)


def fig2b(r: dict, path: str | os.PathLike) -> None:
    """At B = 25 kHz: greedy and TSP vs their speed (PSNR left, arrival right); the agent, the dwell
    rules and the planners, which set their own speeds, as bands."""
    v = np.array(r["velocities"])
    row = next(row for row in r["panel_a"] if row["B"] == 25e3)
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 4.2), gridspec_kw={"width_ratios": [3, 2]})
    for name in (n for n in BANDS if n == "agent" or n in row):
        m, e = row["agent"] if name == "agent" else row[name]["mean_psnr"]
        ax.axhline(
            m, color=STYLE[name]["color"], ls=STYLE[name].get("ls", "-"), label=STYLE[name]["label"] + " (own speed)"
        )
        ax.axhspan(m - e, m + e, color=STYLE[name]["color"], alpha=0.15)
    n = None
    for name in ("greedy", "tsp"):
        p = r["panel_b"][name]
        y = np.array([x[0] for x in p["mean_psnr"]])
        e = np.array([x[1] for x in p["mean_psnr"]])
        st = STYLE[f"{name} v_b*"]
        ax.errorbar(v, y, yerr=e, capsize=3, color=st["color"], marker=st["marker"], label=name.replace("tsp", "TSP"))
        arr = np.array(p["arrived"])
        n = p["episodes"]
        lo, hi = wilson_interval(arr, n)
        yerr = np.clip(np.stack([arr - lo, hi - arr]), 0.0, None)
        ax2.errorbar(v, arr, yerr=yerr, capsize=3, color=st["color"], marker=st["marker"])
    ax.axvline(8.9, color="0.5", ls=":", lw=1)
    ax.set(
        xlabel="baseline speed v_b (m/s)", ylabel="mean PSNR (dB)", title="(b) B = 25 kHz (dotted: the paper's 8.9 m/s)"
    )
    ax2.set(
        xlabel="baseline speed v_b (m/s)",
        ylabel="arrival rate",
        ylim=(min(0.9, ax2.get_ylim()[0]), 1.005),
        title=f"arrival, Wilson 95 % intervals over {n} layouts",
    )
    _finish(fig, ax, ax2, path, fontsize=8, ncol=3)


def fig2c(paths: dict, params: EnvParams, path: str | os.PathLike) -> None:
    """Trajectories on the paper layout, one panel per policy: the path coloured by speed, each device's
    seconds in range written beside it and drawn as a ring whose size grows with them."""
    order = ("agent", "tsp v_b*", *REFERENCES[REFERENCES.index("greedy-dwell") :])
    names = [n for n in order if n in paths]
    fig, axes = plt.subplots(2, 4, figsize=(21, 6.3), sharex=True, sharey=True)
    for ax in axes.ravel()[len(names) :]:
        ax.set_visible(False)
    radius = float(range_radius(params))
    pts = np.concatenate(
        [np.array([[0.0, 0.0], [float(params.Lx), float(params.Ly)]])] + [paths[n]["q"] for n in names]
    )
    lo, hi = pts.min(0) - 10.0, pts.max(0) + 10.0  # the UAV may leave the area (docs/model.md eq. 3.3)
    norm = plt.Normalize(0.0, float(params.v_max))
    for ax, name in zip(axes.ravel(), names):
        p = {k: np.asarray(v) if isinstance(v, list) else v for k, v in paths[name].items()}
        for i, d in enumerate(np.asarray(params.device_pos)):
            ax.add_patch(plt.Circle(d, radius, color="0.88", zorder=0))
            if p["dwell_s"][i] > 0:
                ax.scatter(*d, s=20 + 12 * p["dwell_s"][i], facecolors="none", edgecolors="k", lw=0.8, zorder=3)
                ax.annotate(f"{p['dwell_s'][i]:.0f} s", d, xytext=(6, 6), textcoords="offset points", fontsize=7)
            else:
                ax.plot(*d, "x", color="0.4", ms=5)
        ax.add_patch(plt.Rectangle((0, 0), float(params.Lx), float(params.Ly), fill=False, ls=":", color="0.5"))
        seg = np.stack([p["q"][:-1], p["q"][1:]], axis=1)
        lc = LineCollection(seg, cmap="viridis", norm=norm, lw=2.2)
        lc.set_array(p["speed"][1:])
        ax.add_collection(lc)
        ax.plot(*np.asarray(params.q0), "ko", ms=5)
        ax.plot(*np.asarray(params.q_fin), "k*", ms=10)
        label = "DDQN (ours), seed 0" if name == "agent" else STYLE[name]["label"]
        ax.set_title(
            f"{label}\n{p['mean_psnr']:.1f} dB, {p['coverage']:.0f} covered, {p['mission_time']:.0f} s", fontsize=9
        )
        ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), aspect="equal")
    for ax in axes[-1]:
        ax.set_xlabel("x (m)")
    for ax in axes[:, 0]:
        ax.set_ylabel("y (m)")
    fig.colorbar(lc, ax=axes, shrink=0.8, label="speed (m/s)")
    fig.suptitle(
        f"(c) paper layout, B = {float(params.B) / 1e3:g} kHz: rings and labels give the seconds in range "
        f"of each served device ({radius:.0f} m discs; x: not served)",
        fontsize=10,
        y=0.99,
    )
    save_figure(fig, path, dpi=110, layout=False)  # the colorbar spans all panels: no tight_layout
