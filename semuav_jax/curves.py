"""DeepJSCC PSNR curves C[i, k]: the quality lookup of MODEL.md section 9 (eq. 9.1 in docs/model.md).

A curves file is an ``.npz`` with two entries: ``C`` (float32, images x (M+1), PSNR in dB of
test image i decoded from its first k symbols) and ``meta`` (a JSON string with at least ``M``).
"""

from __future__ import annotations

import dataclasses
import io
import json
import os
from importlib import resources
from pathlib import Path

import numpy as np
import numpy.typing as npt

from semuav_jax.io import atomic_write

DEFAULT_CURVES = "psnr_curves.npz"
REQUIRED_META = ("M",)


@dataclasses.dataclass(frozen=True)
class PSNRCurves:
    """PSNR curves and their metadata; ``C`` has shape (images, M + 1)."""

    C: np.ndarray
    meta: dict

    @property
    def M(self) -> int:
        return self.C.shape[1] - 1

    @property
    def num_images(self) -> int:
        return self.C.shape[0]

    def __post_init__(self) -> None:
        validate_curves(self.C, self.meta)


def validate_curves(C: npt.ArrayLike, meta: dict | None = None, where: str = "curves") -> None:
    """Raise ValueError unless C is a finite 2-D array (images x (M+1)) consistent with ``meta``."""
    C = np.asarray(C)
    if C.ndim != 2 or C.shape[0] < 1 or C.shape[1] < 2:
        raise ValueError(f"{where}: C must have shape (images >= 1, M + 1 >= 2), got {C.shape}")
    if not np.issubdtype(C.dtype, np.floating):
        raise ValueError(f"{where}: C must be a float array of PSNR values in dB, got dtype {C.dtype}")
    if not np.all(np.isfinite(C)):
        raise ValueError(f"{where}: C contains non-finite values (NaN or inf); every PSNR must be finite")
    if np.any(C < 0):
        raise ValueError(
            f"{where}: C holds a PSNR below 0 dB ({float(C.min()):g}); a PSNR of an 8-bit image is >= 0 dB"
        )
    if meta is not None:
        missing = [k for k in REQUIRED_META if k not in meta]
        if missing:
            raise ValueError(f"{where}: metadata lacks {missing}")
        if int(meta["M"]) != C.shape[1] - 1:
            raise ValueError(
                f"{where}: metadata says M = {meta['M']} but C has {C.shape[1]} columns (M + 1 = {C.shape[1]})"
            )


def default_curves_path() -> Path:
    return Path(str(resources.files("semuav_jax") / "data" / DEFAULT_CURVES))


def load_curves(path: str | os.PathLike | None = None) -> PSNRCurves:
    """Load a curves file; the shipped DeepJSCC curves when ``path`` is None."""
    path = Path(path) if path is not None else default_curves_path()
    if not path.is_file():
        hint = " (regenerate with `semuav-jscc curves`)" if path == default_curves_path() else ""
        raise FileNotFoundError(f"PSNR curves file not found: {path}{hint}")
    try:
        with np.load(path, allow_pickle=False) as f:
            entries = {k: f[k] for k in f.files}
    except Exception as e:  # not a zip, truncated, pickled objects
        raise ValueError(f"{path}: not a readable curves file ({type(e).__name__}: {e})") from e
    if "C" not in entries or "meta" not in entries:
        raise ValueError(f"{path}: a curves file needs entries 'C' and 'meta', found {sorted(entries)}")
    try:
        meta = json.loads(str(entries["meta"]))
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: the 'meta' entry is not valid JSON ({e})") from e
    C = entries["C"]
    validate_curves(C, meta, where=str(path))
    return PSNRCurves(C=C.astype(np.float32), meta=meta)


def save_curves(path: str | os.PathLike, C: npt.ArrayLike, meta: dict) -> Path:
    """Write a curves file atomically after validating it."""
    C = np.asarray(C, dtype=np.float32)
    meta = {**meta, "M": int(C.shape[1] - 1)}
    validate_curves(C, meta, where=str(path))
    buf = io.BytesIO()
    np.savez(buf, C=C, meta=np.array(json.dumps(meta, sort_keys=True)))
    return atomic_write(path, buf.getvalue())


def synthetic_curves(images: int = 8, M: int = 256) -> np.ndarray:
    """Monotone stand-in curves for tests and quick experiments, NOT DeepJSCC's: 10 dB at k = 0
    rising to about 30 dB at k = M, a little different per image."""
    k = np.arange(M + 1)
    rows = [10.0 + (20.0 + i) * (1.0 - np.exp(-k / (40.0 + 5 * i))) for i in range(images)]
    return np.stack(rows).astype(np.float32)
