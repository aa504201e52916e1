"""The command-line programs, one module each: ``semuav-train`` (train.py), ``semuav-eval`` (eval.py),
``semuav-sweep`` (sweep.py), ``semuav-jscc`` (jscc.py), ``semuav-baselines`` (baselines.py) and
``semuav-compare`` (compare.py). The root ``train.py`` and ``eval.py``, ``python -m semuav_jax.jscc``,
``python -m baselines.report`` and ``python -m semuav_jax.experiments.learned`` are shims for them.
The top floor: free to import every other part of the package; nothing below imports it."""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path


def interruptible(run: Callable[[list[str] | None], int], argv: list[str] | None, resume_hint: str) -> int:
    """``run(argv)``, with Ctrl-C ending in one line and exit code 130 instead of a traceback (every
    file the commands write is written atomically, so the folder stays consistent)."""
    try:
        return run(argv)
    except KeyboardInterrupt:
        print(f"\n{Path(sys.argv[0]).name}: interrupted; {resume_hint}", file=sys.stderr)
        return 130
