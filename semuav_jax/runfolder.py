"""Output folders the commands own (docs/reliability.md, "Output folders"): a marker of ours
(``.semuav.json``: format, a random run id, the manifest of every file we wrote), written before
anything else; a lock (``.semuav.lock``: pid, host) held for the run's life. Clean-up and
``--overwrite`` remove only files the folder's own manifest lists; a folder without our marker
that holds anything is refused."""

from __future__ import annotations

import atexit
import json
import os
import secrets
import socket
import time
from collections.abc import Iterable
from pathlib import Path

from semuav_jax.io import atomic_write, check_writable_folder

FORMAT = "semuav-jax output folder 1"
MARKER, LOCK = ".semuav.json", ".semuav.lock"


class FolderError(ValueError):
    """A folder we must not write to or is held by another run (one line)."""


def _read_marker(folder: Path) -> dict | None:
    try:
        m = json.loads((folder / MARKER).read_text())
    except (OSError, ValueError):
        return None
    if not (
        isinstance(m, dict)
        and m.get("format") == FORMAT
        and isinstance(m.get("files"), list)
        and all(isinstance(f, str) for f in m["files"])
    ):
        return None
    return m


def owned(folder: str | os.PathLike) -> bool:
    """Whether ``folder`` carries our marker."""
    return _read_marker(Path(folder)) is not None


def foreign_files(folder: Path, listed: Iterable[str] = ()) -> list[str]:
    """Names in ``folder`` we did not write: not the marker or lock, not listed in ``listed``
    (relative paths), not an atomic_write temporary of a listed file, not a folder carrying our
    marker or holding listed files."""
    listed = set(listed)
    top = {p.split("/")[0] for p in listed}
    out = []
    for p in sorted(folder.iterdir()) if folder.is_dir() else []:
        n = p.name
        if n in (MARKER, LOCK) or n in listed or (p.is_dir() and (n in top or owned(p))):
            continue
        if n.endswith(".tmp") and any(n.startswith(f + ".") and len(n) == len(f) + 13 for f in (*listed, MARKER)):
            continue
        out.append(n)
    return out


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class RunFolder:
    """An output folder claimed by this process: locked, marked, and every write recorded.

    ``claim(path, kind, overwrite=..., adopt=...)``: ``overwrite`` removes the files our manifest
    lists first (and starts a new run id); ``adopt`` (a tuple of names) accepts a folder without our
    marker that holds only those names (a run folder of an older version, resumed)."""

    def __init__(self, path: Path, marker: dict, locked: bool = True, readonly: bool = False) -> None:
        self.path, self.marker, self.locked = path, marker, locked  # locked: this claim took the lock
        self.readonly = readonly

    @classmethod
    def view(cls, path: str | os.PathLike) -> RunFolder:
        """The folder as another process of a multi-process run sees it: process 0 claimed it and
        writes; this view reads, and its writes and removals do nothing."""
        path = Path(path)
        return cls(path, _read_marker(path) or {"files": [], "run_id": ""}, locked=False, readonly=True)

    @property
    def run_id(self) -> str:
        return self.marker["run_id"]

    @property
    def files(self) -> list[str]:
        return list(self.marker["files"])

    @classmethod
    def claim(
        cls, path: str | os.PathLike, kind: str, overwrite: bool = False, adopt: tuple = (), what: str = "--out"
    ) -> RunFolder:
        path = Path(path)
        check_writable_folder(path, what)
        marker = _read_marker(path)
        if marker is None:  # checked before we write anything into it (the lock included)
            cls._refuse_foreign(path, adopt, what)
        path.mkdir(parents=True, exist_ok=True)
        locked = _lock(path)  # False: this process holds it already (a claim inside a claim)
        try:
            marker = _read_marker(path)  # again, under the lock
            if marker is None:
                cls._refuse_foreign(path, adopt, what)
                marker = {
                    "format": FORMAT,
                    "kind": kind,
                    "run_id": secrets.token_hex(8),
                    "files": sorted(n for n in adopt if (path / n).exists()),
                }
            elif marker.get("kind") != kind:
                raise FolderError(
                    f"{what} {path} is a {marker.get('kind')} folder, not a {kind} one: choose another {what}"
                )
            folder = cls(path, marker, locked)
            if overwrite:
                folder.remove_listed()
                folder.marker = {**marker, "run_id": secrets.token_hex(8), "files": []}
            folder._save_marker()
            folder.remove_temps()
        except BaseException:
            if locked:
                release(path)
            raise
        return folder

    @staticmethod
    def _refuse_foreign(path: Path, adopt: Iterable[str], what: str) -> None:
        names = foreign_files(path, adopt)
        if names:
            shown = ", ".join(names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else "")
            raise FolderError(
                f"{what} {path} holds files semuav-jax did not write ({shown}) and no {MARKER} marker: "
                f"refusing to write there; choose another {what} (an empty or new folder)"
            )

    def _save_marker(self) -> None:
        if self.readonly:
            return
        atomic_write(self.path / MARKER, json.dumps(self.marker, indent=1).encode())

    def record(self, name: str) -> Path:
        """List ``name`` (relative path) in the manifest (before it is written) and return its path."""
        if name not in self.marker["files"]:
            self.marker["files"] = sorted([*self.marker["files"], name])
            self._save_marker()
        return self.path / name

    def write(self, name: str, data: bytes) -> Path:
        """Record ``name`` and write ``data`` to it atomically."""
        return self.record(name) if self.readonly else atomic_write(self.record(name), data)

    def remove(self, name: str) -> None:
        """Delete a listed file (a file not listed is left alone)."""
        if name in self.marker["files"] and not self.readonly:
            (self.path / name).unlink(missing_ok=True)
            self.marker["files"] = [f for f in self.marker["files"] if f != name]
            self._save_marker()

    def remove_temps(self) -> None:
        """Delete the temporaries a killed atomic_write of a listed file left."""
        for name in () if self.readonly else (*self.marker["files"], MARKER):
            p = self.path / name
            for t in p.parent.glob(f"{p.name}.????????.tmp"):
                t.unlink()

    def remove_listed(self) -> None:
        if self.readonly:
            return
        self.remove_temps()
        for name in self.marker["files"]:
            (self.path / name).unlink(missing_ok=True)
        for d in sorted({str(Path(n).parent) for n in self.marker["files"]} - {"."}, key=len, reverse=True):
            try:
                (self.path / d).rmdir()  # only when empty: a user's file in it stays
            except OSError:
                pass

    def release(self) -> None:
        if self.locked:
            release(self.path)


_HELD: set[Path] = set()


def _lock(path: Path) -> bool:
    """Create ``path/.semuav.lock`` exclusively (True), or find it held by this process (False); a
    lock of a dead process on this host is taken over."""
    lock = path / LOCK
    me = {"pid": os.getpid(), "host": socket.gethostname(), "since": time.strftime("%Y-%m-%d %H:%M:%S")}
    if lock.resolve() in _HELD:
        return False
    for _ in range(3):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            try:
                holder = json.loads(lock.read_text())
                pid, host = int(holder["pid"]), str(holder["host"])
            except (OSError, ValueError, KeyError, TypeError):
                holder = None
            if holder is None:  # being written by its holder this instant, or garbage
                time.sleep(0.2)
                try:
                    holder = json.loads(lock.read_text())
                    pid, host = int(holder["pid"]), str(holder["host"])
                except (OSError, ValueError, KeyError, TypeError):
                    lock.unlink(missing_ok=True)
                    continue
            if host == me["host"] and not _alive(pid):
                lock.unlink(missing_ok=True)  # stale: its process is gone
                continue
            raise FolderError(
                f"{path} is in use by another run (pid {pid} on {host} since {holder.get('since')}; "
                f"remove {lock} if that process is gone)"
            ) from None
        with os.fdopen(fd, "w") as f:
            json.dump(me, f)
        _HELD.add(lock.resolve())
        return True
    raise FolderError(f"could not lock {path} ({lock} keeps changing)")


def release(path: str | os.PathLike) -> None:
    """Remove our lock of ``path`` (no-op if we do not hold it)."""
    lock = (Path(path) / LOCK).resolve()
    if lock in _HELD:
        _HELD.discard(lock)
        lock.unlink(missing_ok=True)


atexit.register(lambda: [release(p.parent) for p in list(_HELD)])
