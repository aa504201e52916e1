"""DeepJSCC's CIFAR-10 reader: genuine Python 2 batches load as with pickle, crafted ones run no code."""

import os
import pickle
import shlex
import struct

import numpy as np
import pytest

from semuav_jax.jscc import data


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
    return {
        b"batch_label": b"a batch",
        b"labels": rng.integers(10, size=n).tolist(),
        b"data": rng.integers(0, 256, (n, 3072), dtype=np.uint8),
        b"filenames": [b"x.png"] * n,
    }


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
