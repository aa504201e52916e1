"""DeepJSCC against bad input and data loss: crafted CIFAR-10 pickles, an --out that already
holds a checkpoint or cannot take one, temporary files of a killed save."""

import os
import pickle
import shlex
import struct

import numpy as np
import pytest

from semuav_jax import io
from semuav_jax.jscc import data
from semuav_jax.jscc import train as train_mod
from semuav_jax.jscc.__main__ import main
from semuav_jax.jscc.train import CKPT_FILE, CONFIG_FILE, TrainConfig, load_config, train

CFG = TrainConfig(steps=2, batch=2, width=4, monotone_weight=0.0, synthetic_fraction=0.0)
PHOTOS = [np.random.default_rng(0).random((40, 40, 3), dtype=np.float32)]
TINY = ["--steps", "2", "--batch", "2", "--width", "4", "--monotone-weight", "0", "--synthetic-fraction", "0"]


class _Py2Pickler(pickle._Pickler):
    """Protocol 2, bytes written as Python 2 ``str`` (BINSTRING), as the CIFAR-10 batches were."""

    dispatch = dict(pickle._Pickler.dispatch)

    def save_str(self, obj):
        n = len(obj)
        self.write((pickle.SHORT_BINSTRING + bytes([n]) if n < 256 else pickle.BINSTRING + struct.pack("<i", n)) + obj)
        self.memoize(obj)

    dispatch[bytes] = save_str


def _write_batch(path, d):
    with open(path, "wb") as f:
        _Py2Pickler(f, protocol=2).dump(d)
    return path


def _batch(rng, n=3):
    return {b"batch_label": b"a batch", b"labels": rng.integers(10, size=n).tolist(),
            b"data": rng.integers(0, 256, (n, 3072), dtype=np.uint8), b"filenames": [b"x.png"] * n}


def test_genuine_cifar10_batches_load_as_with_pickle(tmp_path):
    rng = np.random.default_rng(0)
    files = [_write_batch(tmp_path / f"data_batch_{i}", _batch(rng)) for i in range(1, 6)]
    _write_batch(tmp_path / "test_batch", _batch(rng, 4))
    assert all(b"_codecs" not in f.read_bytes() for f in files)  # no Python 3 bytes: as the real files
    plain = [pickle.loads(f.read_bytes(), encoding="bytes")[b"data"] for f in files]
    expect = np.concatenate(plain).reshape(-1, 3, 32, 32).transpose(0, 2, 3, 1).astype(np.float32) / 255.0
    np.testing.assert_array_equal(data.cifar10_images(tmp_path), expect)
    assert data.cifar10_images(tmp_path, test=True).shape == (4, 32, 32, 3)


class _Attack:
    """Unpickles as ``fn(*args)``."""

    def __init__(self, fn, *args):
        self.fn, self.args = fn, args

    def __reduce__(self):
        return self.fn, self.args


ATTACKS = {
    "open": lambda marker: _Attack(open, str(marker), "w"),
    "system": lambda marker: _Attack(os.system, f"touch {shlex.quote(str(marker))}"),
}


@pytest.mark.parametrize("how", sorted(ATTACKS))
def test_crafted_cifar10_batch_runs_no_code(tmp_path, how):
    marker = tmp_path / "marker"
    attack = ATTACKS[how](marker)
    rng = np.random.default_rng(0)
    for i in range(1, 6):
        _write_batch(tmp_path / f"data_batch_{i}", {**_batch(rng), b"labels": attack} if i == 3 else _batch(rng))
    pickle.loads((tmp_path / "data_batch_3").read_bytes(), encoding="bytes")
    assert marker.exists()  # what pickle.load would do
    marker.unlink()
    name = f"{attack.fn.__module__}.{attack.fn.__name__}"
    with pytest.raises(ValueError, match=rf"data_batch_3 is not a CIFAR-10 batch: it references {name}$"):
        data.cifar10_images(tmp_path)
    assert not marker.exists()


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
    cfg, meta = load_config(out)
    assert cfg == CFG and meta["step"] == 2
    assert len(meta["history"]) == 1  # logged at step 2 only: a new run, not the step-1 one continued
    assert sorted(p.name for p in out.iterdir()) == sorted([CKPT_FILE, CONFIG_FILE, "notes.txt"])
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
    assert load_config(out)[1]["step"] == 2
    assert sorted(p.name for p in out.iterdir()) == sorted([CKPT_FILE, CONFIG_FILE, *others])
