"""The command-line programs, one module each: ``semuav-train`` (train.py), ``semuav-eval`` (eval.py),
``semuav-sweep`` (sweep.py), ``semuav-jscc`` (jscc.py), ``semuav-baselines`` (baselines.py),
``semuav-compare`` (compare.py) and ``semuav-search`` (search.py); ``python -m semuav_jax.cli.NAME``
runs the same. The root ``train.py`` and ``eval.py`` are shims for the first two.
The top floor: free to import every other part of the package; nothing below imports it."""

from __future__ import annotations

import signal
import sys
from collections.abc import Callable
from pathlib import Path

_asked = {"stop": False}


def _on_sigint(signum: int, frame: object) -> None:
    _asked["stop"] = True
    raise KeyboardInterrupt


def _quiet_unraisable(hook: Callable) -> Callable:
    """sys.unraisablehook that drops our own interrupt: Python reports a KeyboardInterrupt raised
    inside a gc callback as 'Exception ignored ... Traceback' on stderr; stop_if_asked acts on it."""

    def quiet(unraisable: object) -> None:
        if not (_asked["stop"] and isinstance(getattr(unraisable, "exc_value", None), KeyboardInterrupt)):
            hook(unraisable)

    return quiet


def stop_if_asked() -> None:
    """Raise KeyboardInterrupt if Ctrl-C was pressed: Python drops the one raised while a garbage
    collector callback (JAX has one) runs, so long loops call this between their steps."""
    if _asked["stop"]:
        raise KeyboardInterrupt


def interruptible(run: Callable[[list[str] | None], int], argv: list[str] | None, resume_hint: str) -> int:
    """``run(argv)``, with Ctrl-C ending in one line and exit code 130 instead of a traceback (every
    file the commands write is written atomically, so the folder stays consistent)."""
    ours = signal.getsignal(signal.SIGINT) is signal.default_int_handler  # not where SIGINT is ignored
    hook = sys.unraisablehook
    if ours:
        signal.signal(signal.SIGINT, _on_sigint)
        sys.unraisablehook = _quiet_unraisable(hook)
    try:
        return run(argv)
    except (KeyboardInterrupt, Exception) as e:
        # a KeyboardInterrupt raised inside C++ (matplotlib's pybind11, a JAX callback) comes back
        # as another exception (TypeError, XlaRuntimeError): after Ctrl-C it is still the interrupt
        if not (isinstance(e, KeyboardInterrupt) or _asked["stop"]):
            raise
        print(f"\n{Path(sys.argv[0]).name}: interrupted; {resume_hint}", file=sys.stderr)
        return 130
    finally:
        if ours:
            signal.signal(signal.SIGINT, signal.default_int_handler)
            sys.unraisablehook = hook
            _asked["stop"] = False
