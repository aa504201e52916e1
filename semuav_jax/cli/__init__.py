"""The command-line programs (``semuav-train``, ``semuav-eval``; the root ``train.py`` and
``eval.py`` are shims for them): the top floor, free to import every other part of the package."""

import sys
from pathlib import Path


def interruptible(run, argv, resume_hint: str) -> int:
    """``run(argv)``, with Ctrl-C ending in one line and exit code 130 instead of a traceback (every
    file the commands write is written atomically, so the folder stays consistent)."""
    try:
        return run(argv)
    except KeyboardInterrupt:
        print(f"\n{Path(sys.argv[0]).name}: interrupted; {resume_hint}", file=sys.stderr)
        return 130
