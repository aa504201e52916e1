"""jscc train against bad input and data loss: bad option values, an --out that already holds a checkpoint or cannot
take one, temporary files of a killed save, a kill at any write of a save, broken or foreign checkpoints, Ctrl-C."""

import dataclasses
import json

import jax
import numpy as np
import pytest
from flax import serialization

from semuav_jax import checkpoint, io
from semuav_jax.cli.jscc import main
from semuav_jax.jscc import data
from semuav_jax.jscc import train as train_mod
from semuav_jax.jscc.train import (
    CKPT_FILE,
    CONFIG_FILE,
    TrainConfig,
    load_checkpoint,
    load_config,
    make_optimizer,
    train,
)
from semuav_jax.runfolder import MARKER

CFG = TrainConfig(steps=2, batch=2, width=4, monotone_weight=0.0, synthetic_fraction=0.0)
PHOTOS = [np.random.default_rng(0).random((40, 40, 3), dtype=np.float32)]
TINY = ["--steps", "2", "--batch", "2", "--width", "4", "--monotone-weight", "0", "--synthetic-fraction", "0"]


def _saved(out, cfg=CFG):
    """(params, opt_state, step, history) of the checkpoint in ``out``."""
    return load_checkpoint(out, cfg, make_optimizer(cfg))


def _no(*a, **k):
    raise AssertionError("reached loading or training")


def _cli_error(capsys, *args) -> str:
    """The one-line error of ``train`` with ``args``, which must exit with status 2."""
    assert main(["train", *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1
    return err


def test_cli_rejects_a_bad_out_before_loading_or_training(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(data, "builtin_train_photos", _no)
    monkeypatch.setattr(train_mod, "train", _no)
    (tmp_path / "f").write_text("x")
    assert "is a file" in _cli_error(capsys, "--out", str(tmp_path / "f"))
    assert "cannot write to --out" in _cli_error(capsys, "--out", str(tmp_path / "f" / "sub"))
    assert "at most one of" in _cli_error(capsys, "--out", str(tmp_path / "new"), "--resume", "--overwrite")
    assert (tmp_path / "f").read_text() == "x" and not (tmp_path / "new").exists()


@pytest.mark.slow
def test_checkpoint_is_replaced_only_with_overwrite(tmp_path, capsys, monkeypatch):
    out = tmp_path / "run"
    train(CFG, PHOTOS, out=out, minutes=1e-9, progress=False, log_every=1)
    saved = {n: (out / n).read_bytes() for n in (CKPT_FILE, CONFIG_FILE)}
    with pytest.raises(ValueError, match="already holds a checkpoint"):
        train(CFG, PHOTOS, out=out, progress=False)
    monkeypatch.setattr(data, "builtin_train_photos", lambda: PHOTOS)
    assert "give --resume to continue it or --overwrite" in _cli_error(capsys, "--out", str(out))
    err = _cli_error(capsys, "--out", str(out), "--resume", "--steps", "5", "--batch", "2")
    assert "--steps 5 (saved 2)" in err and "--batch" not in err
    assert {n: (out / n).read_bytes() for n in saved} == saved
    (out / "notes.txt").write_text("kept")
    assert main(["train", "--out", str(out), "--overwrite", *TINY]) == 0
    cfg, _ = load_config(out)
    _, _, step, history = _saved(out)
    assert cfg == CFG and step == 2
    assert len(history) == 1  # logged at step 2 only: a new run, not the step-1 one continued
    assert sorted(p.name for p in out.iterdir()) == sorted([MARKER, CKPT_FILE, CONFIG_FILE, "notes.txt"])
    assert main(["train", "--out", str(out), "--resume", "--steps", "2"]) == 0  # options as saved: no clash


def _killed_save(path, monkeypatch):
    """What a kill between the write of ``atomic_write``'s temporary file and its rename leaves."""

    def kill(*a):
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr(io.os, "replace", kill)
        m.setattr(io.os, "remove", lambda p: None)
        with pytest.raises(KeyboardInterrupt):
            io.atomic_write(path, bytes(1000))


@pytest.mark.slow
@pytest.mark.parametrize("how", ["resume", "overwrite"])
def test_next_run_removes_temp_files_of_a_killed_save(tmp_path, monkeypatch, how):
    out = tmp_path / "run"
    train(CFG, PHOTOS, out=out, minutes=1e-9, progress=False, log_every=1)
    _killed_save(out / CKPT_FILE, monkeypatch)
    _killed_save(out / CONFIG_FILE, monkeypatch)
    assert len(list(out.glob("*.tmp"))) == 2
    others = ["other.tmp", f"{CKPT_FILE}.tmp", f"{CKPT_FILE}.bak"]
    for n in others:
        (out / n).write_text("not ours")
    train(CFG, PHOTOS, out=out, progress=False, log_every=1, **{how: True})
    assert _saved(out)[2] == 2
    assert sorted(p.name for p in out.iterdir()) == sorted([MARKER, CKPT_FILE, CONFIG_FILE, *others])


@pytest.mark.parametrize(
    "args, msg",
    [
        (["--lr", "nan"], "lr must be finite and > 0"),
        (["--lr", "inf"], "lr must be finite and > 0"),
        (["--steps", "0"], "steps must be a positive integer"),
        (["--synthetic-fraction", "nan"], "synthetic_fraction must be in [0, 1]"),
        (["--snr-db", "inf"], "snr_db must be finite"),
        (["--minutes", "nan"], "--minutes must be positive"),
    ],
)
def test_cli_rejects_bad_values_before_loading_or_training(tmp_path, capsys, monkeypatch, args, msg):
    monkeypatch.setattr(data, "builtin_train_photos", _no)
    monkeypatch.setattr(train_mod, "train", _no)
    assert msg in _cli_error(capsys, "--out", str(tmp_path / "run"), *args)


class _Killed(BaseException):
    """A kill: nothing in the code under test catches it."""


def _writer_killed_at(n, calls):
    """``atomic_write`` that writes normally until its ``n``-th call, which leaves its temporary
    file (a kill before the rename) and raises _Killed; ``calls`` counts the calls."""
    real = io.atomic_write

    def write(path, data):
        calls.append(path.name)
        if len(calls) == n:
            path.parent.mkdir(parents=True, exist_ok=True)
            (path.parent / f"{path.name}.abcdefgh.tmp").write_bytes(data[: len(data) // 2])
            raise _Killed
        return real(path, data)

    return write


KILL_CFG = dataclasses.replace(CFG, steps=3)


def _kill_writes(m, write):
    """``write`` in place of atomic_write for both writers of a run: config.json and the checkpoint."""
    m.setattr(train_mod, "atomic_write", write)
    m.setattr(checkpoint, "atomic_write", write)


def _same_state(a, b):
    """Two load_checkpoint results: bit-identical arrays, the same step and the same logged steps
    and losses (the elapsed seconds differ from run to run)."""
    for x, y in zip(jax.tree_util.tree_leaves(a[:2]), jax.tree_util.tree_leaves(b[:2])):
        np.testing.assert_array_equal(x, y)
    assert a[2] == b[2]
    assert [h[:2] for h in a[3]] == [h[:2] for h in b[3]]


@pytest.mark.slow
def test_kill_at_any_write_of_a_save_resumes_to_the_uninterrupted_run(tmp_path, monkeypatch):
    """A checkpoint after every step (3 saves: config.json + checkpoint, checkpoint, checkpoint);
    a kill at each of these writes, then the same run continued: the checkpoint, with its step and
    history, is that of the uninterrupted run, and config.json holds the same config."""
    ref_calls = []
    with monkeypatch.context() as m:
        _kill_writes(m, _writer_killed_at(0, ref_calls))
        train(KILL_CFG, PHOTOS, out=tmp_path / "ref", progress=False, log_every=1, ckpt_every_s=0.0)
    assert ref_calls == [CONFIG_FILE, CKPT_FILE, CKPT_FILE, CKPT_FILE]
    ref = _saved(tmp_path / "ref", KILL_CFG)
    assert ref[2] == 3 and [h[0] for h in ref[3]] == [1, 2, 3]
    for n in range(1, len(ref_calls) + 1):
        out = tmp_path / f"killed_at_{n}"
        with monkeypatch.context() as m:
            _kill_writes(m, _writer_killed_at(n, []))
            with pytest.raises(_Killed):
                train(KILL_CFG, PHOTOS, out=out, progress=False, log_every=1, ckpt_every_s=0.0)
        if n == 1:  # killed before anything of the run was saved: there is nothing to resume
            with pytest.raises(ValueError, match="not a DeepJSCC checkpoint directory"):
                train(KILL_CFG, PHOTOS, out=out, resume=True, progress=False, log_every=1)
        train(KILL_CFG, PHOTOS, out=out, resume=n > 1, progress=False, log_every=1)
        _same_state(_saved(out, KILL_CFG), ref)
        assert load_config(out)[0] == KILL_CFG
        assert sorted(p.name for p in out.iterdir()) == sorted(
            [MARKER, CKPT_FILE, CONFIG_FILE]
        )  # the temporary file removed


@pytest.mark.slow
def test_resume_refuses_broken_or_foreign_checkpoints_and_reads_old_ones(tmp_path, capsys, monkeypatch):
    out = tmp_path / "run"
    train(CFG, PHOTOS, out=out, minutes=1e-9, progress=False, log_every=1)
    params, opt_state, step, history = _saved(out)
    ckpt, config = (out / CKPT_FILE).read_bytes(), (out / CONFIG_FILE).read_text()
    monkeypatch.setattr(data, "builtin_train_photos", lambda: PHOTOS)
    (out / CKPT_FILE).write_bytes(ckpt[: len(ckpt) // 2])
    assert "unreadable checkpoint" in _cli_error(capsys, "--out", str(out), "--resume")
    (out / CKPT_FILE).write_bytes(ckpt)
    meta = json.loads(config)
    meta["config"]["width"] = 8  # config.json of another network than the checkpoint's
    (out / CONFIG_FILE).write_text(json.dumps(meta))
    assert "do not match" in _cli_error(capsys, "--out", str(out), "--resume")
    # a checkpoint written before checkpoints held their history: step and history from config.json
    (out / CKPT_FILE).write_bytes(serialization.to_bytes({"params": params, "opt_state": opt_state, "step": step}))
    (out / CONFIG_FILE).write_text(json.dumps({**json.loads(config), "step": step, "history": history}))
    assert _saved(out)[2:] == (step, history)
    assert main(["train", "--out", str(out), "--resume"]) == 0
    _, _, step, resumed = _saved(out)
    assert step == 2 and [h[0] for h in resumed] == [1, 2] and resumed[0] == history[0]


def test_cli_ctrl_c_is_one_line_exit_130(tmp_path, capsys, monkeypatch):
    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(data, "builtin_train_photos", lambda: PHOTOS)
    monkeypatch.setattr(train_mod, "train", interrupted)
    assert main(["train", "--out", str(tmp_path / "run"), *TINY]) == 130
    err = capsys.readouterr().err
    assert err.strip() == "interrupted; continue with --resume"
