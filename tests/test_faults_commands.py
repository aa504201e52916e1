"""Commands under faults: jscc curves write only the paths named, diverged training saves nothing, Ctrl-C resumes."""

import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import TRAIN_TINY, start_interruptible
from faults_helpers import ROOT, _err


def _jscc_checkpoint(folder, scale=1.0):
    """A checkpoint of a width-4 DeepJSCC at its initial weights times ``scale``, without training."""
    from semuav_jax.jscc.train import (
        TrainConfig,
        init_params,
        make_optimizer,
        save_checkpoint,
    )

    cfg = TrainConfig(steps=2, batch=2, width=4, monotone_weight=0.0, synthetic_fraction=0.0)
    params = jax.tree.map(lambda x: x * scale, init_params(cfg))
    folder.mkdir()
    save_checkpoint(folder, cfg, params, make_optimizer(cfg).init(params), 2, [(2, 0.0, 1.0)])


@pytest.mark.slow
def test_jscc_curves_write_only_the_paths_named(tmp_path, capsys):
    from semuav_jax.cli.jscc import main
    from semuav_jax.curves import load_curves

    _jscc_checkpoint(tmp_path / "ckpt")
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "deepjscc.msgpack").write_text("the user's model")
    assert main(["curves", "--ckpt", str(tmp_path / "ckpt"), "--out", str(tmp_path / "d" / "c.npz")]) == 0
    assert sorted(p.name for p in (tmp_path / "d").iterdir()) == ["c.npz", "deepjscc.msgpack"]
    assert (tmp_path / "d" / "deepjscc.msgpack").read_text() == "the user's model"
    assert load_curves(tmp_path / "d" / "c.npz").meta["model_file"] is None
    assert (
        main(
            [
                "curves",
                "--ckpt",
                str(tmp_path / "ckpt"),
                "--out",
                str(tmp_path / "d" / "c.npz"),
                "--model-out",
                str(tmp_path / "d" / "m.msgpack"),
            ]
        )
        == 0
    )
    assert sorted(p.name for p in (tmp_path / "d").iterdir()) == ["c.npz", "deepjscc.msgpack", "m.msgpack"]


@pytest.mark.slow
def test_jscc_curves_of_a_non_finite_checkpoint_write_nothing(tmp_path, capsys):
    """A NaN model neither replaces the user's deepjscc.msgpack beside --out nor writes curves."""
    from semuav_jax.cli.jscc import main

    _jscc_checkpoint(tmp_path / "ckpt", jnp.nan)
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "deepjscc.msgpack").write_text("the user's model")
    code, err = _err(capsys, main, ["curves", "--ckpt", str(tmp_path / "ckpt"), "--out", str(tmp_path / "d" / "c.npz")])
    assert code == 2 and "not finite" in err
    assert [p.name for p in (tmp_path / "d").iterdir()] == ["deepjscc.msgpack"]
    assert (tmp_path / "d" / "deepjscc.msgpack").read_text() == "the user's model"
    code, err = _err(
        capsys,
        main,
        [
            "curves",
            "--ckpt",
            str(tmp_path / "ckpt"),
            "--out",
            str(tmp_path / "d" / "c.npz"),
            "--model-out",
            str(tmp_path / "d" / "c.npz"),
        ],
    )
    assert code == 2 and "--model-out must be a .msgpack path other than --out" in err


@pytest.mark.slow
def test_jscc_train_that_diverges_exits_2_and_saves_nothing(tmp_path, capsys, monkeypatch):
    from semuav_jax.cli.jscc import main
    from semuav_jax.jscc import data

    monkeypatch.setattr(
        data, "builtin_train_photos", lambda: [np.random.default_rng(0).random((40, 40, 3), dtype=np.float32)]
    )
    code, err = _err(
        capsys,
        main,
        [
            "train",
            "--out",
            str(tmp_path / "j"),
            "--steps",
            "2",
            "--batch",
            "2",
            "--width",
            "4",
            "--monotone-weight",
            "0",
            "--synthetic-fraction",
            "0",
            "--snr-db",
            "-1000",
        ],
    )
    lines = [ln for ln in err.replace("\r", "\n").splitlines() if "error" in ln]  # beside the progress bar's
    assert code == 2 and len(lines) == 1 and "error: training diverged at step 2" in lines[0], err  # the last step
    assert not (tmp_path / "j" / "checkpoint.msgpack").exists() and not (tmp_path / "j" / ".semuav.lock").exists()


@pytest.mark.slow
def test_train_that_diverges_exits_2_without_a_finished_run(tmp_path):
    out = tmp_path / "r"
    res = subprocess.run(
        [sys.executable, str(ROOT / "train.py"), *TRAIN_TINY, "--lr", "1e38", "--out", str(out)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=900,
        check=False,
    )
    assert res.returncode == 2 and "training diverged (non-finite loss or weights)" in res.stderr, res.stderr
    assert res.stderr.strip().splitlines()[-1].startswith("train.py: error:")
    assert not (out / "model.msgpack").exists() and not (out / "checkpoint.msgpack").exists()


@pytest.mark.slow
def test_ctrl_c_before_the_first_checkpoint_then_resume_finishes(tmp_path):
    """A real SIGINT during the first segment: exit 130, no checkpoint; --resume restarts from chunk 0
    and finishes the run."""
    import signal
    import time

    out = tmp_path / "r"
    p = start_interruptible([sys.executable, str(ROOT / "train.py"), *TRAIN_TINY, "--out", str(out)])
    try:
        deadline = time.time() + 600
        while not (out / "config.json").exists() and time.time() < deadline and p.poll() is None:
            time.sleep(0.2)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=600)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait(timeout=60)
    assert p.returncode == 130 and "--resume or the same command starts it again" in err, err
    assert not (out / "checkpoint.msgpack").exists()
    res = subprocess.run(
        [sys.executable, str(ROOT / "train.py"), "--out", str(out), "--resume", "--eval-episodes", "0"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=900,
        check=False,
    )
    assert res.returncode == 0 and "no checkpoint yet: starting its run from chunk 0" in res.stdout, res.stderr
    assert (out / "model.msgpack").is_file()
