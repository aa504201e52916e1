"""Split a batch over worker processes that run one function of a NumPy-only module file.

``map_chunks`` starts ``python workers.py <module file> <function>`` per chunk, sends the chunk as an
npz on stdin and reads the function's arrays back as an npz from stdout. The worker loads the module
by its file path, not as ``baselines.<name>`` (the package ``__init__`` imports JAX): such a module
must import nothing from ``baselines`` at top level. Unlike a multiprocessing pool this needs no
``__main__`` guard in the caller and never forks JAX.
"""

from __future__ import annotations

import importlib.util
import io
import subprocess
import sys

import numpy as np


def _npz_bytes(arrays: dict) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def map_chunks(module_file, function: str, batched: dict, shared: dict | None = None, workers: int = 2) -> dict:
    """Run ``function(**chunk, **shared)`` on ``workers`` chunks of the leading axis of ``batched``.

    ``function`` returns a dict of arrays with the same leading axis; the chunks' results are
    concatenated in order.
    """
    batched = {k: np.asarray(v) for k, v in batched.items()}
    n = len(next(iter(batched.values())))
    bounds = [(int(idx[0]), int(idx[-1]) + 1) for idx in np.array_split(np.arange(n), max(1, workers)) if len(idx)]
    procs = [
        subprocess.Popen([sys.executable, __file__, str(module_file), function], stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        for _ in bounds
    ]
    for proc, (lo, hi) in zip(procs, bounds):  # all started first: their imports overlap
        proc.stdin.write(_npz_bytes({**{k: v[lo:hi] for k, v in batched.items()}, **(shared or {})}))
        proc.stdin.close()
    outs = [proc.stdout.read() for proc in procs]
    for proc in procs:
        if proc.wait() != 0:
            raise RuntimeError(f"worker {module_file}:{function} failed with exit code {proc.returncode}")
    results = [np.load(io.BytesIO(out)) for out in outs]
    return {k: np.concatenate([r[k] for r in results]) for k in results[0].files}


def _main() -> None:
    """Worker: load the module file, call the function on the npz from stdin, write its npz to stdout."""
    module_file, function = sys.argv[1:3]
    spec = importlib.util.spec_from_file_location("_worker_module", module_file)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    data = np.load(io.BytesIO(sys.stdin.buffer.read()))
    out = getattr(module, function)(**{k: data[k] for k in data.files})
    sys.stdout.buffer.write(_npz_bytes(out))
    sys.stdout.buffer.flush()


if __name__ == "__main__":
    _main()
