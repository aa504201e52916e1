"""The fixed "paper layout" of MODEL.md section 1: N = 10 devices drawn once (NumPy seed 2024,
uniform in the 1000 x 600 m area) and frozen here as constants."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from semuav_jax.params import EnvParams, make_params

if TYPE_CHECKING:
    from semuav_jax.curves import PSNRCurves

PAPER_DEVICE_POS = np.array(
    [
        [675.8, 128.6],
        [309.5, 479.7],
        [995.8, 85.3],
        [78.7, 108.5],
        [359.6, 101.8],
        [588.8, 370.1],
        [105.4, 339.4],
        [4.6, 279.1],
        [975.6, 479.7],
        [596.8, 195.2],
    ],
    np.float32,
)
PAPER_DEVICE_IMG = np.array([1, 1, 6, 3, 6, 2, 5, 6, 6, 1], np.int32)

SCENARIOS = ("fixed", "random")


def scenario_params(scenario: str, curves: PSNRCurves | np.ndarray | None = None, **overrides: Any) -> EnvParams:
    """EnvParams of a named scenario: ``fixed`` (the paper layout above) or ``random`` (a new layout per reset).

    Image indices of the paper layout are taken modulo the number of images of ``curves``.
    """
    if scenario not in SCENARIOS:
        raise ValueError(f"scenario must be one of {SCENARIOS}, got {scenario!r}")
    if scenario == "random":
        return make_params(curves, N=len(PAPER_DEVICE_POS), layout="random", **overrides)
    probe = make_params(curves, N=len(PAPER_DEVICE_POS))
    img = PAPER_DEVICE_IMG % probe.C.shape[0]
    return make_params(probe.C, device_pos=PAPER_DEVICE_POS, device_img=img, layout="fixed", **overrides)
