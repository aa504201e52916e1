"""Confidence intervals, the one statistics module: t intervals for means (few seeds or many
episodes), Wilson score intervals for proportions (arrival rates)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy import stats


def mean_ci(x: npt.ArrayLike, level: float = 0.95) -> tuple[float, float | None]:
    """Mean of x and the half-width of its Student-t confidence interval (None for a single value:
    one sample has no interval)."""
    x = np.asarray(x, np.float64).ravel()
    if len(x) < 2:
        return float(x.mean()), None
    return float(x.mean()), float(stats.t.ppf(0.5 + level / 2, len(x) - 1) * x.std(ddof=1) / np.sqrt(len(x)))


def wilson_interval(
    p: float | np.ndarray, n: int | np.ndarray, z: float = 1.96
) -> tuple[float | np.ndarray, float | np.ndarray]:
    """Wilson score 95 % interval (lo, hi) of a proportion p observed over n trials; unlike
    p ± z sqrt(p(1-p)/n) it stays inside [0, 1] and is not empty at p = 0 or 1."""
    p = np.asarray(p, np.float64)
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def pm(half: float | None, digits: int = 2) -> str:
    """``± half`` for a table, ``± n/a`` when there is no interval (one sample)."""
    return "± n/a" if half is None else f"± {half:.{digits}f}"
