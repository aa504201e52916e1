"""Ctrl-C in the commands: one line, exit code 130, a folder that resumes; also when Python drops
the KeyboardInterrupt (raised while a garbage-collector callback runs)."""

import gc
import os
import signal
import sys

import pytest
from conftest import ROOT, start_interruptible, train_options
from test_train import _train

from semuav_jax.cli import interruptible, stop_if_asked


def test_a_dropped_keyboard_interrupt_still_stops_at_the_next_step(capsys):
    """The interrupt lands inside a gc callback, where Python drops it: no 'Exception ignored' traceback
    on stderr, the loop's next stop_if_asked ends the command with 130, the steps after it never run;
    an unrelated exception dropped the same way is still reported."""
    steps = []
    fired = []

    def ctrl_c_in_gc(phase, info):
        if phase == "start" and not fired:
            fired.append(phase)
            os.kill(os.getpid(), signal.SIGINT)

    def run(argv):
        for i in range(5):
            stop_if_asked()
            if i == 2:
                gc.callbacks.append(ctrl_c_in_gc)
                try:
                    gc.collect()
                finally:
                    gc.callbacks.remove(ctrl_c_in_gc)
            steps.append(i)
        return 0

    def other_error_in_gc(phase, info):
        if phase == "start":
            raise ValueError("a real bug in a callback")

    # as in a foreground process: a test run in the background inherits SIGINT ignored
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    reported = []
    hook, sys.unraisablehook = sys.unraisablehook, reported.append
    try:
        assert interruptible(run, [], "rerun it") == 130
        assert fired and steps == [0, 1, 2]
        err = capsys.readouterr().err
        assert err.strip() == f"{os.path.basename(sys.argv[0])}: interrupted; rerun it" and not reported
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
        assert sys.unraisablehook == reported.append
        gc.callbacks.append(other_error_in_gc)
        try:
            assert interruptible(lambda argv: gc.collect() * 0, [], "") == 0  # the flag does not outlive its command
        finally:
            gc.callbacks.remove(other_error_in_gc)
        assert [type(u.exc_value) for u in reported] == [ValueError]
    finally:
        sys.unraisablehook = hook
        signal.signal(signal.SIGINT, before)


def test_an_interrupt_that_c_code_turned_into_another_error_is_still_the_interrupt(capsys):
    """Ctrl-C inside matplotlib's pybind11 code comes back as a TypeError: after Ctrl-C it ends with
    130 and one line; the same error without Ctrl-C keeps its traceback."""

    def run(argv):
        try:
            os.kill(os.getpid(), signal.SIGINT)
        except KeyboardInterrupt:
            raise TypeError("affine_transform(): incompatible function arguments") from None
        return 0

    def broken(argv):
        raise TypeError("a real bug")

    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        assert interruptible(run, [], "rerun it") == 130
        assert capsys.readouterr().err.strip() == f"{os.path.basename(sys.argv[0])}: interrupted; rerun it"
        with pytest.raises(TypeError, match="a real bug"):
            interruptible(broken, [], "rerun it")
    finally:
        signal.signal(signal.SIGINT, before)


@pytest.mark.slow
def test_sigint_stops_with_one_line_and_resumes(curves_file, tmp_path):
    """Ctrl-C during training: exit 130, a one-line message, no traceback; --resume then finishes."""
    import signal
    import time

    out = tmp_path / "r"
    longer = train_options(total_steps=2000, segments=10, eval_episodes=0)
    proc = start_interruptible(
        [sys.executable, str(ROOT / "train.py"), "--curves", curves_file, "--out", str(out), *longer]
    )
    deadline = time.time() + 300
    while not (out / "checkpoint.msgpack").exists() and time.time() < deadline:
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 130, err
    assert "interrupted" in err and "--resume" in err and "Traceback" not in err
    assert not (out / "model.msgpack").exists()
    res = _train("--out", str(out), "--resume")  # the saved run config, its evaluation options too
    assert res.returncode == 0, res.stderr
    assert (out / "model.msgpack").is_file()
