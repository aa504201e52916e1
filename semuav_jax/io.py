"""Atomic file writes: a temporary file in the same folder, then ``os.replace``, so an
interrupted run never leaves a half-written result, checkpoint, curves file or figure; and the
checks an output folder passes before a long run writes to it."""

from __future__ import annotations

import io
import os
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from matplotlib.figure import Figure

_UMASK = os.umask(0)
os.umask(_UMASK)


def atomic_write(path: str | os.PathLike, data: bytes) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; give the file the usual permissions
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return path


def save_figure(fig: Figure, path: str | os.PathLike, dpi: int = 120, layout: bool = True, crop: bool = True) -> Path:
    """Write the matplotlib figure ``fig`` atomically in the format of ``path``'s suffix (.png,
    .pdf, .svg) and close it. ``layout``: ``tight_layout`` first; ``crop``: the bounding box of
    what is drawn, so legends placed outside the axes are kept."""
    import matplotlib.pyplot as plt

    if layout:
        fig.tight_layout()
    buf = io.BytesIO()
    fmt = Path(path).suffix.lstrip(".").lower() or "png"
    fig.savefig(buf, format=fmt, dpi=dpi, **({"bbox_inches": "tight"} if crop else {}))
    plt.close(fig)
    return atomic_write(path, buf.getvalue())


def check_writable_folder(path: str | os.PathLike, what: str = "--out") -> Path:
    """ValueError (one line) unless files can be written into the folder ``path`` (made later if
    absent): checked before a long run starts, not when it saves."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ValueError(f"{what} {path} is a file, not a folder")
    base = path
    while not base.exists():
        base = base.parent
    if not base.is_dir():
        raise ValueError(f"cannot write to {what} {path}: {base} is a file")
    try:
        with tempfile.TemporaryFile(dir=base):
            pass
    except OSError as e:
        raise ValueError(f"cannot write to {what} {path}: {e.strerror or e}") from None
    return path


def remove_stale_temps(folder: Path, names: Iterable[str]) -> None:
    """Remove the temporary files of :func:`atomic_write` (``<name>.<8 random characters>.tmp``)
    that a save killed before its rename left in ``folder``, for each file name in ``names``."""
    for n in names:
        for t in Path(folder).glob(f"{n}.????????.tmp"):
            t.unlink()
