"""Pictures of an episode as it unfolds (docs/env_api.md, "Rendering"): the area, the devices with
their range discs coloured by the share of their image received (m_n / M, eq. 3.7), the UAV and
its trail, the time and the mean PSNR so far (eq. 8.1). matplotlib's Agg canvas, no display needed.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Rectangle

from semuav_jax.control import range_radius
from semuav_jax.params import EnvParams

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.cm import ScalarMappable

    from semuav_jax.env import EnvState

SHARE_CMAP = colormaps["viridis"]
SHARE_NORM = Normalize(0.0, 1.0)


def view_limits(params: EnvParams, trails: Iterable[npt.ArrayLike] = ()) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) corners that show the area, q0, q_fin and every point of ``trails``, 20 m of margin."""
    pts = [
        np.array([[0.0, 0.0], [float(params.Lx), float(params.Ly)]]),
        np.asarray(params.q0)[None],
        np.asarray(params.q_fin)[None],
    ] + [np.asarray(t).reshape(-1, 2) for t in trails]
    pts = np.concatenate(pts)
    return pts.min(0) - 20.0, pts.max(0) + 20.0


def draw(
    ax: Axes,
    params: EnvParams,
    dev_pos: npt.ArrayLike,
    m: npt.ArrayLike,
    x: npt.ArrayLike,
    trail: npt.ArrayLike,
    t: int,
    mean_psnr: float,
    title: str | None = None,
    limits: tuple[np.ndarray, np.ndarray] | None = None,
) -> None:
    """Draw one moment on ``ax``: ``dev_pos`` (N, 2), ``m`` (N,) symbols received, ``x`` (N,) bool
    transmitting, ``trail`` (T, 2) the UAV's positions up to now (last: where it is), slot ``t``."""
    dev_pos, share = np.asarray(dev_pos), np.clip(np.asarray(m) / float(params.M), 0.0, 1.0)
    x, trail = np.asarray(x, bool), np.asarray(trail).reshape(-1, 2)
    radius = float(range_radius(params))
    ax.add_patch(Rectangle((0, 0), float(params.Lx), float(params.Ly), fill=False, ls=":", color="0.5"))
    for d, s, tx in zip(dev_pos, share, x):
        ax.add_patch(Circle(d, radius, color=SHARE_CMAP(SHARE_NORM(s)), alpha=0.3 + 0.3 * tx, lw=0, zorder=1))
        if tx:  # an active link: the UAV is in range and receiving from this device in slot t
            ax.plot([d[0], trail[-1, 0]], [d[1], trail[-1, 1]], color="C1", lw=0.8, zorder=2)
    ax.scatter(
        dev_pos[:, 0],
        dev_pos[:, 1],
        c=share,
        cmap=SHARE_CMAP,
        norm=SHARE_NORM,
        s=28,
        marker="s",
        edgecolors=np.where(x, "C1", "k"),
        linewidths=np.where(x, 1.6, 0.6),
        zorder=3,
    )
    ax.add_patch(Circle(np.asarray(params.q_fin), float(params.r_arr), fill=False, color="k", lw=0.8, zorder=2))
    ax.plot(*np.asarray(params.q0), "ko", ms=4, zorder=3)
    ax.plot(*np.asarray(params.q_fin), "k*", ms=9, zorder=3)
    ax.plot(trail[:, 0], trail[:, 1], color="C3", lw=1.4, zorder=4)
    ax.plot(*trail[-1], marker="o", mfc="none", mec="C3", mew=2.0, ms=9, zorder=5)  # hollow: the device below shows
    lo, hi = view_limits(params, [trail]) if limits is None else limits
    ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), aspect="equal")
    ax.tick_params(labelsize=7)
    clock = (
        f"t = {t * float(params.tau):5.1f} s of {params.K * float(params.tau):.0f} s   mean PSNR {mean_psnr:5.2f} dB"
    )
    ax.set_title(clock if title is None else f"{title}\n{clock}", fontsize=8)


def figure_rgb(fig: Figure) -> np.ndarray:
    """The (H, W, 3) uint8 pixels of a matplotlib ``Figure`` drawn on an Agg canvas."""
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


def rgb_frame(
    state: EnvState,
    params: EnvParams,
    trail: npt.ArrayLike,
    title: str | None = None,
    size: tuple[float, float] = (6.4, 4.4),
    dpi: int = 100,
) -> np.ndarray:
    """An (H, W, 3) uint8 picture of one ``EnvState`` (NumPy or JAX leaves) with the UAV's ``trail``
    (T, 2), a colour bar of the received share beside it."""
    fig = Figure(figsize=size, dpi=dpi)
    ax = fig.add_subplot()
    draw(ax, params, state.dev_pos, state.m, state.x, trail, int(state.t), float(np.mean(state.phi)), title)
    fig.colorbar(_share_mappable(), ax=ax, shrink=0.7, label="share of the image received")
    fig.tight_layout()
    return figure_rgb(fig)


def _share_mappable() -> ScalarMappable:
    from matplotlib.cm import ScalarMappable

    return ScalarMappable(norm=SHARE_NORM, cmap=SHARE_CMAP)
