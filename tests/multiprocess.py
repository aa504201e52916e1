"""Launch a command as N local processes of one distributed run (loopback, a free port, bounded
timeouts), and end every process started, whatever happens."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def environment(devices: int = 1) -> dict:
    return {
        **os.environ,
        "JAX_PLATFORMS": "cpu",
        "PYTHONPATH": str(ROOT),
        "XLA_FLAGS": f"--xla_force_host_platform_device_count={devices}",
    }


def start(args: list[str], processes: int, timeout_s: float = 20, devices: int = 1, logs: Path | None = None):
    """Popen objects of ``python ARGS --coordinator 127.0.0.1:PORT --num-processes N --process-id I``;
    stdout and stderr go to files in ``logs`` (or are discarded)."""
    port = free_port()
    procs = []
    for i in range(processes):
        with (
            open(logs / f"p{i}.out" if logs else os.devnull, "wb") as out,
            open(logs / f"p{i}.err" if logs else os.devnull, "wb") as err,
        ):  # the child keeps its own copies
            procs.append(
                subprocess.Popen(
                    [
                        sys.executable,
                        *args,
                        "--coordinator",
                        f"127.0.0.1:{port}",
                        "--num-processes",
                        str(processes),
                        "--process-id",
                        str(i),
                        "--dist-timeout",
                        str(timeout_s),
                    ],
                    cwd=ROOT,
                    env=environment(devices),
                    stdout=out,
                    stderr=err,
                )
            )
    return procs


def wait_all(procs, limit_s: float) -> list[int]:
    """Exit codes of every process, waiting at most ``limit_s`` in all; the rest are killed (None)."""
    end = time.monotonic() + limit_s
    codes = []
    try:
        for p in procs:
            try:
                codes.append(p.wait(max(0.1, end - time.monotonic())))
            except subprocess.TimeoutExpired:
                codes.append(None)
    finally:
        end_all(procs)
    return codes


def end_all(procs) -> None:
    for p in procs:
        if p.poll() is None:
            p.kill()
            p.wait(10)


def run(args: list[str], processes: int, limit_s: float = 300, **kw):
    """Exit codes and (stdout, stderr) texts of a distributed run of ``args``."""
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        logs = Path(d)
        codes = wait_all(start(args, processes, logs=logs, **kw), limit_s)
        texts = [
            ((logs / f"p{i}.out").read_text(errors="replace"), (logs / f"p{i}.err").read_text(errors="replace"))
            for i in range(processes)
        ]
    return codes, texts


def single(args: list[str], devices: int = 1, limit_s: float = 300) -> subprocess.CompletedProcess:
    """``python ARGS`` in one process with ``devices`` host devices."""
    return subprocess.run(
        [sys.executable, *args],
        cwd=ROOT,
        env=environment(devices),
        capture_output=True,
        text=True,
        timeout=limit_s,
        check=False,
    )
