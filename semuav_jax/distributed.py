"""Run one command on several processes and hosts with JAX's distributed runtime (docs/scaling.md).

``add_options`` gives every command ``--coordinator HOST:PORT --num-processes N --process-id I
--dist-timeout S``; :func:`initialize` starts ``jax.distributed`` with them (``--coordinator
auto``: the cluster environment JAX detects, e.g. Slurm). Process 0 binds the coordinator to the
given address only. Every wait is bounded by S seconds (default 60): a peer that never starts
fails the initialization, one that dies or hangs is noticed by a watchdog within S, and the
process then ends with one line on stderr and exit code 1 (:func:`abort`), without waiting for
its peers and without writing a result (only :func:`is_main` writes).
"""

from __future__ import annotations

import argparse
import atexit
import os
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

DEFAULT_TIMEOUT_S = 60
_ALIVE, _DONE = "semuav/alive/", "semuav/done/"
_state = {"active": False}


class DistributedError(Exception):
    """A bad distributed option, or a start the runtime refused: one line, exit code 2."""


def add_options(parser: argparse.ArgumentParser) -> None:
    """The distributed options of every command (``parser``: an argparse parser)."""
    g = parser.add_argument_group("several processes or hosts (docs/scaling.md)")
    g.add_argument(
        "--coordinator",
        default=None,
        metavar="HOST:PORT",
        help="process 0's address and a free port; 'auto': the cluster's environment (Slurm); default: one process",
    )
    g.add_argument("--num-processes", type=int, default=None, help="processes in the run (with --coordinator)")
    g.add_argument("--process-id", type=int, default=None, help="this process's rank, 0 .. N-1 (with --coordinator)")
    g.add_argument(
        "--dist-timeout",
        type=float,
        default=DEFAULT_TIMEOUT_S,
        help="seconds a start or a silent peer may take before the run ends (default: %(default)s)",
    )


def check_options(args: argparse.Namespace) -> None:
    """DistributedError (one line) for inconsistent distributed options."""
    if args.dist_timeout < 2:
        raise DistributedError(f"--dist-timeout must be >= 2 s, got {args.dist_timeout}")
    if args.coordinator is None:
        if args.num_processes not in (None, 1) or args.process_id not in (None, 0):
            raise DistributedError("--num-processes and --process-id need --coordinator HOST:PORT")
        return
    if args.coordinator == "auto":
        return
    host, _, port = args.coordinator.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise DistributedError(f"--coordinator must be HOST:PORT, got {args.coordinator!r}")
    if args.num_processes is None or args.process_id is None:
        raise DistributedError("--coordinator HOST:PORT needs --num-processes and --process-id")
    if args.num_processes < 1 or not 0 <= args.process_id < args.num_processes:
        raise DistributedError(
            f"--process-id must be in 0 .. {args.num_processes - 1} and --num-processes >= 1, "
            f"got {args.process_id} of {args.num_processes}"
        )


def initialize(args: argparse.Namespace) -> None:
    """Start the distributed runtime if the options ask for it (no-op otherwise, or if started before)."""
    check_options(args)
    if args.coordinator is None or _state["active"]:
        return
    import jax
    from jax._src import xla_bridge
    from jax.extend.backend import clear_backends

    if xla_bridge.backends_are_initialized():  # by an import (gymnax makes arrays): nothing computed yet
        clear_backends()
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    t = int(args.dist_timeout)
    # the runtime's own limits are a backstop at twice ours: when it gives up it aborts with a long log
    kw = {"initialization_timeout": 2 * t, "heartbeat_timeout_seconds": 2 * t, "shutdown_timeout_seconds": t}
    if args.coordinator != "auto":
        kw.update(
            coordinator_address=args.coordinator,
            num_processes=args.num_processes,
            process_id=args.process_id,
            coordinator_bind_address=args.coordinator,
        )
    where = args.coordinator if args.coordinator != "auto" else "the cluster's coordinator"
    message = f"could not start the distributed run at {where}: not every process joined within {args.dist_timeout:g} s"
    timer = threading.Timer(args.dist_timeout, abort, (message,))
    timer.daemon = True
    timer.start()
    try:
        jax.distributed.initialize(**kw)
        jax.devices()  # the global topology exchange: also waits for every process
    except Exception as e:  # noqa: BLE001  the runtime raises several types (RuntimeError, XlaRuntimeError, ...)
        raise DistributedError(f"could not start the distributed run at {where}: {_first_line(e)}") from None
    finally:
        timer.cancel()
    _state.update(active=True, timeout=args.dist_timeout)
    threading.Thread(target=_watch, args=(args.dist_timeout,), daemon=True).start()


def active() -> bool:
    return _state["active"]


def is_main() -> bool:
    """True in process 0 (or a run of one process): the one process that writes files."""
    import jax

    return jax.process_index() == 0


def abort(message: str, code: int = 1) -> None:
    """End this process now: one line on stderr, exit ``code`` (the peers notice within the timeout)."""
    sys.stdout.flush()
    print(f"\n{Path(sys.argv[0]).name}: error: {message}", file=sys.stderr, flush=True)  # after a progress bar
    os._exit(code)


def guarded(run: Callable[[list[str] | None], int | None], argv: list[str] | None) -> int | None:
    """``run(argv)``; in a distributed run an exception (a lost peer's collective fails, or any error in
    this process) or a failed exit code ends the process at once (one line), since its peers cannot go
    on without it."""
    try:
        code = run(argv)
    except KeyboardInterrupt:
        if not _state["active"]:
            raise
        abort(f"process {_process_id()} interrupted; the files saved so far are consistent", 130)
    except Exception as e:
        if not _state["active"]:
            raise
        abort(f"distributed run stopped on process {_process_id()}: {_first_line(e)}")
    if _state["active"] and code not in (0, None):  # the command said why: its peers must not wait at exit
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


def barrier(name: str) -> None:
    """Wait (at most the timeout) until every process gets here, e.g. before reading a file process 0 wrote."""
    if _state["active"]:
        from jax._src import distributed

        distributed.global_state.client.wait_at_barrier(f"semuav/{name}", int(_state["timeout"] * 1000))


def _process_id() -> int:
    from jax._src import distributed

    return distributed.global_state.process_id


def _first_line(e: Exception) -> str:
    text = str(e).strip().splitlines()
    return (text[0] if text else type(e).__name__)[:300]


def _watch(timeout: float) -> None:
    """Every second, bump this process's counter in the coordinator's key-value store and read the
    others'; a peer whose counter has not moved for timeout / 2 s (and that has not finished), or a
    coordinator that does not answer for as long, ends this process (the runtime's own heartbeat
    would only abort later, with a long log)."""
    from jax._src import distributed

    gs = distributed.global_state
    client, me = gs.client, gs.process_id
    limit = timeout / 2
    seen = {p: (None, time.monotonic()) for p in range(gs.num_processes) if p != me}
    last_ok = [time.monotonic()]
    done = threading.Event()
    atexit.register(lambda: (done.set(), _try(client.key_value_set, f"{_DONE}{me}", "1", allow_overwrite=True)))

    def judge():
        while not done.wait(1):
            now = time.monotonic()
            if now - last_ok[0] > limit:
                abort(f"process {me} lost the coordinator at {gs.coordinator_address} (no answer for {limit:g} s)")
            stale = [p for p, (_, t) in seen.items() if now - t > limit]
            if stale:
                abort(f"process {me}: peer process {stale[0]} stopped answering for {limit:g} s (died or hung)")

    threading.Thread(target=judge, daemon=True).start()
    beat = 0
    while not done.is_set():
        beat += 1
        if _try(client.key_value_set, f"{_ALIVE}{me}", str(beat), allow_overwrite=True) is not _FAILED:
            last_ok[0] = time.monotonic()
        for p in list(seen):
            if _try(client.key_value_try_get, f"{_DONE}{p}") not in (_FAILED, None):
                del seen[p]  # finished: waits for the others at exit
                continue
            value = _try(client.key_value_try_get, f"{_ALIVE}{p}")
            if value is not _FAILED and value != seen[p][0]:
                seen[p] = (value, time.monotonic())
        time.sleep(1)


_FAILED = object()


def _try(f: Callable, *args: Any, **kw: Any):
    """f(...), or _FAILED if it raises (a key not set yet, or the coordinator gone: judged by time)."""
    try:
        return f(*args, **kw)
    except Exception:  # noqa: BLE001
        return _FAILED
