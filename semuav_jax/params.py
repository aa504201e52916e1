"""Environment parameters: every default of MODEL.md section 1 (and 2, 4, 6), with validation.

Physical values are pytree leaves (traced, so a sweep over them is a ``vmap``); shapes and
modes (``K``, ``M``, ``levels``, ``reward_mode``, ``layout``) are static fields. ``N`` is the
first dimension of ``device_pos`` and the number of images is the first dimension of ``C``.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct
from jax.typing import ArrayLike

from semuav_jax.curves import PSNRCurves, load_curves, validate_curves

REWARD_MODES = ("paper", "gain")
LAYOUTS = ("random", "fixed")


@struct.dataclass
class EnvParams:
    """Parameters of one scenario (MODEL.md sections 1, 2, 4, 6); build with :func:`make_params`."""

    C: jax.Array  # (images, M + 1) PSNR curves in dB, MODEL.md section 9
    device_pos: jax.Array  # (N, 2) positions used by the fixed layout, metres
    device_img: jax.Array  # (N,) image index per device used by the fixed layout
    Lx: float = 1000.0
    Ly: float = 600.0
    tau: float = 0.5
    H: float = 100.0
    D_com: float = 105.0
    P_n: float = 1e-3
    noise: float = 1e-9
    B: float = 20e3
    q0: jax.Array = struct.field(default_factory=lambda: jnp.array([0.0, 300.0]))
    q_fin: jax.Array = struct.field(default_factory=lambda: jnp.array([1000.0, 300.0]))
    r_arr: float = 15.0
    a_max: float = 5.0
    v_max: float = 25.0
    bs_pos: jax.Array = struct.field(default_factory=lambda: jnp.array([500.0, 300.0]))
    bs_h: float = 25.0
    P_b: float = 1.0
    B_b: float = 100e3
    L_cmd: float = 64.0
    proc_max: float = 0.1
    beta: float = 16.0
    r_g: float = 500.0
    P_miss: float = 500.0
    kappa_d: float = 1.0
    airspace_margin: float = float("inf")  # metres beyond the area that end the episode; inf: no bound
    kappa_c: float = 10.0  # MODEL.md gives no value; 10 measured best (docs/ddqn.md)
    eps: float = 1e-6
    # Air-to-ground channel, urban (Al-Hourani 2014), MODEL.md section 2
    los_a: float = 9.61
    los_b: float = 0.16
    eta_los: float = 1.0
    eta_nlos: float = 20.0
    f_c: float = 2e9
    c: float = 3e8
    # Static: shapes and modes
    K: int = struct.field(pytree_node=False, default=250)
    M: int = struct.field(pytree_node=False, default=256)
    levels: int = struct.field(pytree_node=False, default=3)
    reward_mode: str = struct.field(pytree_node=False, default="paper")
    layout: str = struct.field(pytree_node=False, default="random")

    @property
    def N(self) -> int:
        return self.device_pos.shape[-2]


def make_params(
    curves: PSNRCurves | np.ndarray | None = None,
    N: int | None = None,
    device_pos: ArrayLike | None = None,
    device_img: ArrayLike | None = None,
    **overrides: Any,
) -> EnvParams:
    """Build and validate :class:`EnvParams`.

    ``curves``: a :class:`PSNRCurves`, a bare array C, or None for the shipped DeepJSCC curves.
    ``device_pos`` (N, 2) and ``device_img`` (N,) set the fixed layout (``layout="fixed"``); for
    the random layout only their shape matters and they default to a placeholder of N devices
    (default 10; N given with ``device_pos`` must equal its length).
    """
    if curves is None:
        curves = load_curves()
    C = curves.C if isinstance(curves, PSNRCurves) else np.asarray(curves)
    validate_curves(C)
    if "M" not in overrides:
        overrides["M"] = C.shape[1] - 1
    if N is not None and (not isinstance(N, (int, np.integer)) or isinstance(N, bool)):
        raise ValueError(f"N must be an integer, got {N!r}")
    if device_pos is None:
        if overrides.get("layout") == "fixed":
            raise ValueError("layout='fixed' needs device_pos (N, 2) in metres")
        device_pos = np.zeros((10 if N is None else max(N, 0), 2), np.float32)
    device_pos = np.asarray(device_pos, np.float32)
    if device_pos.ndim != 2 or device_pos.shape[1] != 2:
        raise ValueError(f"device_pos must have shape (N, 2), got {device_pos.shape}")
    if N is not None and N != device_pos.shape[0]:
        raise ValueError(f"N = {N} disagrees with device_pos, which holds {device_pos.shape[0]} devices")
    for k, v in overrides.items():
        if k in _SCALARS and np.ndim(v) != 0:
            raise ValueError(f"{k} must be a scalar, got shape {np.shape(v)}")
    if device_img is None:
        device_img = np.arange(device_pos.shape[0]) % C.shape[0]
    if overrides.get("airspace_margin", 0.0) is None:
        overrides["airspace_margin"] = float("inf")
    floats = {k: float(v) if np.ndim(v) == 0 and k not in _STATIC else v for k, v in overrides.items()}
    for k in ("q0", "q_fin", "bs_pos"):
        if k in floats:
            floats[k] = jnp.asarray(floats[k], jnp.float32)
    unknown = set(floats) - set(EnvParams.__dataclass_fields__)
    if unknown:
        raise ValueError(f"unknown parameter(s) {sorted(unknown)}")
    params = EnvParams(
        C=jnp.asarray(C, jnp.float32),
        device_pos=jnp.asarray(device_pos),
        device_img=jnp.asarray(device_img, jnp.int32),
        **floats,
    )
    validate_params(params)
    return params


_STATIC = ("K", "M", "levels", "reward_mode", "layout")

# (name, lower bound, inclusive?) for the positive scalars; checked on every entry of a sweep.
_POSITIVE = (
    "Lx",
    "Ly",
    "tau",
    "H",
    "P_n",
    "noise",
    "B",
    "r_arr",
    "a_max",
    "v_max",
    "P_b",
    "B_b",
    "L_cmd",
    "beta",
    "f_c",
    "c",
    "eps",
    "los_a",
    "los_b",
)
_NON_NEGATIVE = ("proc_max", "bs_h", "r_g", "P_miss", "kappa_d", "kappa_c", "airspace_margin", "eta_los", "eta_nlos")
_VECTORS = ("C", "device_pos", "device_img", "q0", "q_fin", "bs_pos")
_SCALARS = tuple(k for k in EnvParams.__dataclass_fields__ if k not in _VECTORS and k not in _STATIC)
# lengths and speeds the dynamics square (|v|^2, distances^2): |x| must stay below sqrt(float32 max)
_SQUARED = ("Lx", "Ly", "H", "D_com", "r_arr", "a_max", "v_max", "bs_h", "q0", "q_fin", "bs_pos", "device_pos")
SQUARE_MAX = 1.8e19
_MAY_BE_INF = ("device_img", "airspace_margin")


def params_valid(params: EnvParams) -> jax.Array:
    """Traced bool: the checks of :func:`validate_params` that traced values can fail (finite,
    positive, D_com > H, image indices in range). ``episode_metrics`` reports it as ``valid``,
    since a value inside ``jit``/``vmap`` cannot raise."""
    ok = jnp.asarray(True)
    for name in params.__dataclass_fields__:
        if name in _STATIC or name in _MAY_BE_INF:
            continue
        ok &= jnp.all(jnp.isfinite(jnp.asarray(getattr(params, name), jnp.float32)))
    for name in _POSITIVE:
        ok &= jnp.all(jnp.asarray(getattr(params, name)) > 0)
    for name in _NON_NEGATIVE:
        ok &= jnp.all(jnp.asarray(getattr(params, name)) >= 0)
    for name in _SQUARED:
        ok &= jnp.all(jnp.abs(jnp.asarray(getattr(params, name))) < SQUARE_MAX)
    ok &= jnp.all(params.D_com > params.H)
    img = jnp.asarray(params.device_img)
    return ok & jnp.all((img >= 0) & (img < params.C.shape[0]))


def _float32(v: ArrayLike) -> np.ndarray:
    with np.errstate(over="ignore"):
        return np.asarray(v, np.float32)


def _concrete(x: Any) -> np.ndarray | None:
    """The value of x as a NumPy array, or None while it is traced (validation runs outside jit)."""
    if isinstance(x, jax.core.Tracer):
        return None
    return np.asarray(x)


def validate_params(params: EnvParams) -> None:
    """Raise ValueError naming the parameter and its allowed range (MODEL.md section 1)."""
    if params.reward_mode not in REWARD_MODES:
        raise ValueError(f"reward_mode must be one of {REWARD_MODES}, got {params.reward_mode!r}")
    if params.layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {LAYOUTS}, got {params.layout!r}")
    for name, value, lo in (("K", params.K, 1), ("M", params.M, 1), ("levels", params.levels, 2)):
        if not isinstance(value, (int, np.integer)) or value < lo:
            raise ValueError(f"{name} must be an integer >= {lo}, got {value!r}")
    if params.device_pos.shape[-2] < 1:
        raise ValueError(f"N must be >= 1 device, got {params.device_pos.shape[-2]}")
    vals = {k: _concrete(getattr(params, k)) for k in params.__dataclass_fields__ if k not in _STATIC}
    for name, v in vals.items():
        if v is not None and name not in _MAY_BE_INF and not np.all(np.isfinite(_float32(v))):
            raise ValueError(f"{name} must be finite (in float32, |x| < 3.4e38), got {v}")
    for name in _POSITIVE:
        v = vals[name]
        if v is not None and not np.all(v > 0):
            raise ValueError(f"{name} must be > 0, got {v}")
    for name in _NON_NEGATIVE:
        v = vals[name]
        if v is not None and not np.all(v >= 0):
            raise ValueError(f"{name} must be >= 0, got {v}")
    for name in _SQUARED:
        v = vals[name]
        if v is not None and not np.all(np.abs(v) < SQUARE_MAX):
            raise ValueError(
                f"{name} must be below {SQUARE_MAX:.1e} in magnitude (its square must be finite in float32), got {v}"
            )
    H, D = vals["H"], vals["D_com"]
    if H is not None and D is not None and not np.all(D > H):
        raise ValueError(
            f"D_com must be > H (the 3-D range must exceed the altitude, or no device is ever in range), "
            f"got D_com={D}, H={H}"
        )
    Lx, Ly = vals["Lx"], vals["Ly"]
    if Lx is not None and Ly is not None:
        for name in ("q0", "q_fin", "bs_pos", "device_pos"):
            p = vals[name]
            if p is None:
                continue
            if p.shape[-1] != 2:
                raise ValueError(f"{name} must have a last dimension of 2 (x, y), got shape {p.shape}")
            x, y = p[..., 0], p[..., 1]
            if not (np.all((x >= 0) & (x <= Lx)) and np.all((y >= 0) & (y <= Ly))):
                raise ValueError(f"{name} must lie inside the area [0, Lx] x [0, Ly] = [0, {Lx}] x [0, {Ly}], got {p}")
    C = vals["C"]
    if C is not None:
        validate_curves(C, {"M": params.M}, where="C")
        img = vals["device_img"]
        if img is not None:
            if img.shape[-1:] != params.device_pos.shape[-2:-1]:
                raise ValueError(f"device_img must have shape (N,) = ({params.N},), got {img.shape}")
            if not np.all((img >= 0) & (img < C.shape[-2])):
                raise ValueError(f"device_img must index an image in [0, {C.shape[-2] - 1}], got {img}")
