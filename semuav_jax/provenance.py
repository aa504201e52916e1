"""What produced a result: package version, git commit and the hash of the PSNR curves, stamped
into every results JSON so a number can be traced to the code and data that made it."""

from __future__ import annotations

import hashlib
import os
import subprocess
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from semuav_jax.params import EnvParams


def version() -> str:
    try:
        return metadata.version("semuav-jax")
    except metadata.PackageNotFoundError:
        return "unknown"


def git_commit() -> str:
    """The checkout's commit (with ``+dirty`` when tracked files differ), or ``unknown`` outside git."""
    here = Path(__file__).resolve().parent
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, check=True, timeout=10
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=here,
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return commit + ("+dirty" if dirty else "")


def curves_hash(C: npt.ArrayLike) -> str:
    """sha256 of the PSNR curves C as float32 (the array the simulator uses)."""
    return hashlib.sha256(np.ascontiguousarray(np.asarray(C, np.float32)).tobytes()).hexdigest()


def file_hash(path: str | os.PathLike) -> str:
    """sha256 of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def provenance(params: EnvParams) -> dict:
    return {"version": version(), "commit": git_commit(), "curves_sha256": curves_hash(params.C)}
