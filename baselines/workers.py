"""Split a batch over worker processes that run one function of a NumPy-only module file.

``map_chunks`` starts ``python workers.py <module file> <function>`` per chunk, sends the chunk as an
npz on stdin and reads the function's arrays back as an npz from stdout. The worker imports the module
as ``<package>.<name>`` under a bare stand-in for its package, whose ``__init__`` (which imports JAX)
it never runs: such a module may import, at top level, only siblings that are themselves free of JAX
and of the package's ``__init__``. Unlike a multiprocessing pool this needs no
``__main__`` guard in the caller and never forks JAX. A worker runs its chunk in pieces of
``PIECE`` items and reports each on stderr, so the caller's progress bar moves while it solves.
"""

from __future__ import annotations

import importlib
import io
import subprocess
import sys
import threading
import types
from pathlib import Path

import numpy as np
import numpy.typing as npt

PIECE = 16  # items a worker solves between two progress reports
SHARED = "__shared__"  # the npz entry naming the arrays that are not split into pieces


def _npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def map_chunks(
    module_file: str | Path,
    function: str,
    batched: dict[str, npt.ArrayLike],
    shared: dict[str, npt.ArrayLike] | None = None,
    workers: int = 2,
    desc: str | None = None,
) -> dict[str, np.ndarray]:
    """Run ``function(**chunk, **shared)`` on ``workers`` chunks of the leading axis of ``batched``.

    ``function`` returns a dict of arrays with the same leading axis; the chunks' results are
    concatenated in order. A progress bar (``desc``, items done) moves as the workers report.
    """
    from tqdm import tqdm

    batched = {k: np.asarray(v) for k, v in batched.items()}
    n = len(next(iter(batched.values())))
    bounds = [(int(idx[0]), int(idx[-1]) + 1) for idx in np.array_split(np.arange(n), max(1, workers)) if len(idx)]
    procs = [
        subprocess.Popen(
            [sys.executable, __file__, str(module_file), function],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        for _ in bounds
    ]
    bar = tqdm(total=n, desc=desc or function, unit="item", leave=False, dynamic_ncols=True)
    errors = [[] for _ in procs]

    def follow(proc: subprocess.Popen, err: list[str]) -> None:
        # progress lines are item counts; anything else is kept for the error message
        for line in proc.stderr:
            text = line.decode(errors="replace").strip()
            if text.isdigit():
                bar.update(int(text))
            elif text:
                err.append(text)

    readers = [threading.Thread(target=follow, args=(p, e), daemon=True) for p, e in zip(procs, errors)]
    for r in readers:
        r.start()
    for proc, (lo, hi) in zip(procs, bounds):  # all started first: their imports overlap
        proc.stdin.write(
            _npz_bytes(
                {
                    **{k: v[lo:hi] for k, v in batched.items()},
                    **(shared or {}),
                    SHARED: np.array(sorted(shared or {}), dtype=str),
                }
            )
        )
        proc.stdin.close()
    outs = [proc.stdout.read() for proc in procs]
    for r in readers:
        r.join()
    bar.close()
    for proc, err in zip(procs, errors):
        if proc.wait() != 0:
            raise RuntimeError(
                f"worker {module_file}:{function} failed with exit code {proc.returncode}: "
                + (err[-1] if err else "no message")
            )
    results = [np.load(io.BytesIO(out)) for out in outs]
    return {k: np.concatenate([r[k] for r in results]) for k in results[0].files}


def _load(module_file: str | Path) -> types.ModuleType:
    """The module of ``module_file`` imported as ``<package>.<name>``, the package a bare module
    whose ``__init__`` is not run."""
    path = Path(module_file).resolve()
    package = types.ModuleType(path.parent.name)
    package.__path__ = [str(path.parent)]
    sys.modules[package.__name__] = package
    return importlib.import_module(f"{package.__name__}.{path.stem}")


def _main() -> None:
    """Worker: load the module file, call the function on the npz from stdin, write its npz to stdout."""
    module_file, function = sys.argv[1:3]
    module = _load(module_file)
    data = np.load(io.BytesIO(sys.stdin.buffer.read()))
    names = set(data[SHARED].tolist())
    shared = {k: data[k] for k in data.files if k in names}
    batched = {k: data[k] for k in data.files if k not in names and k != SHARED}
    n = len(next(iter(batched.values())))
    pieces = []
    for lo in range(0, n, PIECE):
        pieces.append(getattr(module, function)(**{k: v[lo : lo + PIECE] for k, v in batched.items()}, **shared))
        print(min(PIECE, n - lo), file=sys.stderr, flush=True)
    out = {k: np.concatenate([p[k] for p in pieces]) for k in pieces[0]}
    sys.stdout.buffer.write(_npz_bytes(out))
    sys.stdout.buffer.flush()


if __name__ == "__main__":
    _main()
