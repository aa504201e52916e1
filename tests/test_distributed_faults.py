"""Bounded failures of a distributed run: bad options, a peer that never starts or is lost mid-run (docs/scaling.md)."""

import argparse
import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest
from conftest import GRID
from multiprocess import ROOT, end_all, environment, free_port, start

from semuav_jax import distributed


def _options(argv):
    p = argparse.ArgumentParser()
    distributed.add_options(p)
    return p.parse_args(argv)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--num-processes", "2"], "need --coordinator"),
        (["--coordinator", "127.0.0.1"], "HOST:PORT"),
        (["--coordinator", "127.0.0.1:99999", "--num-processes", "2", "--process-id", "0"], "HOST:PORT"),
        (["--coordinator", "127.0.0.1:1234", "--num-processes", "2"], "needs --num-processes and --process-id"),
        (["--coordinator", "127.0.0.1:1234", "--num-processes", "2", "--process-id", "2"], "0 .. 1"),
        (["--dist-timeout", "0.5"], ">= 2 s"),
    ],
)
def test_bad_distributed_options_are_one_line_errors(argv, message):
    with pytest.raises(distributed.DistributedError, match=message):
        distributed.check_options(_options(argv))
    distributed.check_options(_options([]))  # one process: nothing to check


def test_a_peer_that_never_starts_ends_the_run_within_the_timeout():
    """Process 0 of 2 alone: the start gives up after --dist-timeout with one line, exit code 1."""
    script = textwrap.dedent("""
        import argparse, time
        from semuav_jax import distributed
        p = argparse.ArgumentParser()
        distributed.add_options(p)
        args = p.parse_args()
        print(time.time(), flush=True)
        distributed.initialize(args)
        print("started")
    """)
    p = subprocess.run(
        [
            sys.executable,
            "-c",
            script,
            "--coordinator",
            f"127.0.0.1:{free_port()}",
            "--num-processes",
            "2",
            "--process-id",
            "0",
            "--dist-timeout",
            "5",
        ],
        cwd=ROOT,
        env=environment(),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    waited = time.time() - float(p.stdout.split()[0])
    assert p.returncode == 1, p.stderr[-2000:]
    assert "started" not in p.stdout
    assert (
        p.stderr.strip()
        .splitlines()[-1]
        .endswith(
            "error: could not start the distributed run at 127.0.0.1:"
            + p.args[4].split(":")[1]
            + ": not every process joined within 5 s"
        )
    )
    assert 5 <= waited < 5 + 5  # the timeout, plus the interpreter's exit


def _wait_for(path, limit_s):
    end = time.monotonic() + limit_s
    while time.monotonic() < end:
        if path.exists() and any(path.iterdir()):
            return True
        time.sleep(0.2)
    return False


@pytest.mark.slow
@pytest.mark.parametrize("fault", ["kill", "hang"])
def test_a_peer_lost_mid_run_ends_the_other_within_the_timeout(tmp_path, fault):
    """Process 1 is killed (or stopped) after process 0 saved its first item: process 0 ends within
    --dist-timeout with one line and exit code 1, and writes no table."""
    grid = tmp_path / "grid.json"
    grid.write_text(json.dumps({**GRID, "seeds": list(range(20))}))
    timeout_s = 20
    procs = start(
        ["-m", "semuav_jax.cli.sweep", str(grid), "--out", str(tmp_path / "out")], 2, timeout_s=timeout_s, logs=tmp_path
    )
    try:
        assert _wait_for(tmp_path / "out" / "items", 240), (tmp_path / "p0.err").read_text()[-2000:]
        os.kill(procs[1].pid, signal.SIGKILL if fault == "kill" else signal.SIGSTOP)
        t0 = time.monotonic()
        code = procs[0].wait(timeout_s + 15)
        wall = time.monotonic() - t0
    finally:
        if fault == "hang":
            os.kill(procs[1].pid, signal.SIGCONT)
        end_all(procs)
    err = (tmp_path / "p0.err").read_text().strip().splitlines()
    print(f"{fault}: process 0 ended {wall:.1f} s after the fault: {err[-1]}")
    assert code == 1, err[-5:]
    assert wall <= timeout_s
    assert "error:" in err[-1] and ("peer process 1" in err[-1] or "distributed run stopped" in err[-1])
    assert not (tmp_path / "out" / "sweep.csv").exists() and not (tmp_path / "out" / "sweep.json").exists()
