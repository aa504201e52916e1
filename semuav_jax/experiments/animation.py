"""Episodes flown side by side on one layout, as an animated GIF (``eval.py --animate``, README).

:func:`animate` takes any ``{name: trace}`` (one episode each, as ``rollout(..., trace=True)``
records it) and draws one panel per name with :func:`semuav_jax.render.draw`;
:func:`paper_layout_traces` flies the agent and the references on the paper layout.
"""

from __future__ import annotations

import io
import json
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import jax
import numpy as np
from matplotlib.figure import Figure
from PIL import Image
from tqdm import tqdm

from semuav_jax.io import atomic_write
from semuav_jax.params import EnvParams
from semuav_jax.render import draw, figure_rgb, view_limits

if TYPE_CHECKING:
    from semuav_jax.agents.config import DDQNConfig
    from semuav_jax.agents.network import QNetwork

REFERENCES = {
    "greedy v_b*": "greedy",
    "tsp v_b*": "TSP",
    "tsp-dwell": "TSP-dwell",
    "planner": "open-loop planner",
    "exact planner": "exact planner",
}  # traced_runs' names (TSP-dwell when its knobs are given)


def episode_path(trace: dict, params: EnvParams) -> dict:
    """One traced episode from t = 0 to its end: q (L + 1, 2) from q0, m, x and phi (L + 1, N), L
    the slots until ``done`` (K if never)."""
    done = np.asarray(trace["done"])
    slots = int(np.argmax(done)) + 1 if done.any() else len(done)
    N = np.asarray(trace["m"]).shape[-1]
    first = {"q": np.asarray(params.q0, np.float32)[None], "m": np.zeros((1, N)), "x": np.zeros((1, N), bool)}
    out = {k: np.concatenate([first[k], np.asarray(trace[k])[:slots]]) for k in ("q", "m", "x")}
    out["phi"] = np.asarray(trace["phi"])[:slots]
    return out


def animate(
    traces: dict[str, dict],
    params: EnvParams,
    path: str | os.PathLike,
    fps: int = 8,
    stride: int = 2,
    cols: int = 2,
    panel: tuple[float, float] = (4.8, 3.1),
    dpi: int = 80,
    hold_s: float = 2.0,
    progress: bool = False,
) -> Path:
    """Write an animated GIF of ``traces`` ({panel title: one episode's trace with q, m, x, phi and
    done per slot}) on the fixed layout of ``params``: every ``stride``-th slot, ``fps`` frames a
    second, the last frame held ``hold_s`` seconds; an episode that ended stays on its last slot.
    ``progress``: a tqdm bar over the frames."""
    if params.layout != "fixed":
        raise ValueError("animate draws one layout: params.layout must be 'fixed'")
    if not traces:
        raise ValueError("animate needs at least one trace")
    paths = {name: episode_path(tr, params) for name, tr in traces.items()}
    limits = view_limits(params, [p["q"] for p in paths.values()])
    phi0 = _initial_psnr(params)
    longest = max(len(p["q"]) - 1 for p in paths.values())
    slots = [*range(0, longest, stride), longest]
    rows = -(-len(paths) // cols)
    frames = []
    for t in tqdm(slots, desc="frames", unit="frame", disable=not progress, dynamic_ncols=True):
        fig = Figure(figsize=(panel[0] * min(cols, len(paths)), panel[1] * rows + 0.6), dpi=dpi)
        axes = fig.subplots(rows, min(cols, len(paths)), squeeze=False).ravel()
        for ax, (name, p) in zip(axes, paths.items()):
            s = min(t, len(p["q"]) - 1)
            psnr = float(np.mean(p["phi"][s - 1])) if s > 0 else phi0
            done = " (ended)" if s == len(p["q"]) - 1 else ""
            draw(ax, params, params.device_pos, p["m"][s], p["x"][s], p["q"][: s + 1], s, psnr, name + done, limits)
        for ax in axes[len(paths) :]:
            ax.set_axis_off()
        fig.suptitle(
            f"paper layout, B = {float(params.B) / 1e3:g} kHz; device colour: share of its image "
            "received (dark none, yellow all); orange: transmitting",
            fontsize=8,
        )
        fig.subplots_adjust(
            left=0.06, right=0.99, bottom=0.05, top=1 - 0.8 / fig.get_figheight(), wspace=0.15, hspace=0.35
        )  # room for the titles (equal-aspect axes defeat tight_layout)
        frames.append(Image.fromarray(figure_rgb(fig)).quantize(colors=64, method=Image.Quantize.MEDIANCUT))
    buf = io.BytesIO()
    durations = [round(1000 / fps)] * (len(frames) - 1) + [round(1000 * max(hold_s, 1 / fps))]
    frames[0].save(
        buf, format="GIF", save_all=True, append_images=frames[1:], duration=durations, loop=0, optimize=True
    )
    return atomic_write(path, buf.getvalue())


def _initial_psnr(params: EnvParams) -> float:
    """Mean PSNR at t = 0, nothing received: eq. 3.8 at m = 0 (the C[img, 0] of each device)."""
    C = np.asarray(params.C)
    return float(np.mean(C[np.asarray(params.device_img), 0]))


def shipped_tuned_speeds(folder: str | os.PathLike, B: float) -> dict | None:
    """v_b* of greedy and TSP, and the dwell rules' knobs where recorded, at bandwidth B from a run
    folder's eval.json (None if it has no tuning at B)."""
    f = Path(folder) / "eval.json"
    if not f.is_file():
        return None
    r = json.loads(f.read_text())
    bandwidths = [row["B"] for row in r.get("rows", [])]
    if B not in bandwidths or "tuning" not in r:
        return None
    j = bandwidths.index(B)
    return {n: r["tuning"][n]["v_star"][j] for n in ("greedy", "tsp")} | {
        n: tuple(r["tuning"][n]["knobs"][j]) for n in ("greedy-dwell", "tsp-dwell") if n in r["tuning"]
    }


def paper_layout_traces(
    network: QNetwork, nets: Any, config: DDQNConfig, fixed: EnvParams, tuned: dict
) -> dict[str, dict]:
    """{panel title: trace} of seed 0 of the agent, greedy and TSP at their tuned speeds ``tuned``
    ({"greedy": v, "tsp": v}, plus "tsp-dwell": (v_c, k*, margin) when known), the open-loop and
    the exact planner, one episode each on ``fixed``'s layout (test key 0, as Fig. 2c)."""
    from semuav_jax.experiments.behaviour import traced_runs
    from semuav_jax.keys import TEST_SEED, episode_keys

    runs = traced_runs(
        network, jax.tree.map(lambda x: x[:1], nets), config, episode_keys(TEST_SEED, 1), fixed, tuned, workers=1
    )
    labels = {"agent seed 0": "DDQN (ours)"} | {
        k: v + (f", {tuned[k.split()[0]]:g} m/s" if "v_b*" in k else "") for k, v in REFERENCES.items() if k in runs
    }
    return {labels[k]: jax.tree.map(lambda x: np.asarray(x)[0], runs[k][1]) for k in labels}
