"""DeepJSCC (MODEL.md section 9): channel pieces, training, curves file and the shipped curves."""

import dataclasses
import pickle

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from semuav_jax.cli.jscc import main
from semuav_jax.curves import load_curves, save_curves
from semuav_jax.jscc import M, data, power_normalize, prefix_mask, quantize_iq, truncate
from semuav_jax.jscc.config import TrainConfig
from semuav_jax.jscc.evaluate import default_model_path, load_model
from semuav_jax.jscc.model import DeepJSCC, latent_to_symbols, received_plane, symbols_to_latent
from semuav_jax.jscc.train import train
from semuav_jax.provenance import file_hash


def _complex(key, shape):
    a, b = jax.random.split(key)
    return 3.0 * jax.random.normal(a, shape) + 1j * jax.random.normal(b, shape)


def test_power_normalization_unit_average_power():
    s = power_normalize(_complex(jax.random.PRNGKey(0), (5, M)))
    np.testing.assert_allclose(np.mean(np.abs(s) ** 2, axis=1), 1.0, rtol=1e-5)


def test_truncation_zeroes_exactly_the_tail_and_renormalizes():
    s = power_normalize(_complex(jax.random.PRNGKey(1), (4, M)))
    k = jnp.array([0, 1, 100, M])
    t = np.asarray(truncate(s, k))
    for row, kk in zip(t, np.asarray(k)):
        assert np.all(row[kk:] == 0)
        assert np.all(row[:kk] != 0)
        if kk:
            np.testing.assert_allclose(np.mean(np.abs(row[:kk]) ** 2), 1.0, rtol=1e-5)
    assert np.asarray(prefix_mask(k)).sum(axis=1).tolist() == [0, 1, 100, M]


def test_latent_is_channel_major_and_invertible():
    z = jax.random.normal(jax.random.PRNGKey(2), (2, 8, 8, 8))
    s = latent_to_symbols(z)
    assert s.shape == (2, M)
    np.testing.assert_allclose(s[0, 0], z[0, 0, 0, 0] + 1j * z[0, 0, 1, 0])
    np.testing.assert_allclose(s[0, 32], z[0, 0, 0, 1] + 1j * z[0, 0, 1, 1])
    np.testing.assert_allclose(symbols_to_latent(s), z)


def test_dead_leaves_replace_a_fraction_of_the_batch():
    photos = list(data.builtin_test_set()[0][:6])
    plain = data.sample_batch(photos, 16, np.random.default_rng([0, 5]))
    mixed = data.sample_batch(photos, 16, np.random.default_rng([0, 5]), synthetic=0.25)
    np.testing.assert_array_equal(mixed[4:], plain[4:])  # the photo crops draw exactly as without
    assert not np.array_equal(mixed[:4], plain[:4])
    leaves = data.dead_leaves(50, np.random.default_rng(1))
    assert leaves.shape == (50, 32, 32, 3) and leaves.dtype == np.float32
    assert 0.0 <= leaves.min() and leaves.max() <= 1.0
    # piecewise constant: every image holds few distinct colours, unlike a photo crop
    assert max(len(np.unique(im.reshape(-1, 3), axis=0)) for im in leaves) <= 49
    np.testing.assert_array_equal(leaves, data.dead_leaves(50, np.random.default_rng(1)))


def test_mask_input_decoder_sees_exactly_the_received_entries():
    s = power_normalize(_complex(jax.random.PRNGKey(3), (3, M)))
    k = jnp.array([0, 17, M])
    rx = jnp.where(prefix_mask(k), quantize_iq(truncate(s, k)), 0.0)
    plane = np.asarray(received_plane(rx))
    assert plane.shape == (3, 8, 8, 8)
    assert plane.sum(axis=(1, 2, 3)).tolist() == [0, 34, 2 * M]
    np.testing.assert_array_equal(plane, np.asarray(symbols_to_latent(prefix_mask(k) * (1.0 + 1.0j))))
    net = DeepJSCC(8, mask_input=True)
    shapes = jax.eval_shape(
        net.init, jax.random.PRNGKey(0), jnp.zeros((1, 32, 32, 3)), jnp.array([M]), jax.random.PRNGKey(1), 30.0
    )["params"]
    assert shapes["decoder"]["Conv_0"]["kernel"].shape[2] == 16  # 8 latent + 8 mask channels


def test_quantizer_is_8_bit_and_clips():
    x = jnp.linspace(-6.0, 6.0, 10001)
    q = np.asarray(quantize_iq(x + 1j * x))
    assert len(np.unique(q.real)) == 256
    assert q.real.min() == pytest.approx(-4.0) and q.real.max() == pytest.approx(4.0)
    inside = np.abs(np.asarray(x)) <= 4
    assert np.max(np.abs(q.real - np.asarray(x))[inside]) <= 4.0 / 255 + 1e-6


@pytest.mark.slow
def test_short_training_lowers_loss_and_resume_is_exact(tmp_path):
    photos = [data.builtin_test_set()[0][i] for i in range(6)]
    cfg = TrainConfig(steps=40, batch=8, width=8, lr=3e-3, monotone_weight=0.0, synthetic_fraction=0.0)
    from semuav_jax.jscc.train import init_params, load_checkpoint, make_optimizer

    x = np.stack(photos)
    net = DeepJSCC(cfg.width)

    def loss(params):
        y = net.apply({"params": params}, x, jnp.full((6,), M), jax.random.PRNGKey(0), cfg.snr_db)
        return float(jnp.mean((y - x) ** 2))

    before = loss(init_params(cfg))
    params, _ = train(cfg, photos, out=tmp_path / "a", progress=False)
    assert loss(params) < 0.7 * before
    train(cfg, photos, out=tmp_path / "b", minutes=1e-9, progress=False, log_every=10)
    assert load_checkpoint(tmp_path / "b", cfg, make_optimizer(cfg))[2] == 10
    resumed, _ = train(cfg, photos, out=tmp_path / "b", resume=True, progress=False, log_every=10)
    for a, b in zip(jax.tree_util.tree_leaves(params), jax.tree_util.tree_leaves(resumed)):
        np.testing.assert_array_equal(a, b)


@pytest.mark.slow
def test_monotone_finetune_starts_from_run_and_resume_is_exact(tmp_path):
    photos = [data.builtin_test_set()[0][i] for i in range(6)]
    base = TrainConfig(steps=10, batch=4, width=8, lr=3e-3, monotone_weight=0.0)
    start, _ = train(base, photos, out=tmp_path / "base", progress=False)
    cfg = TrainConfig(steps=20, batch=4, width=8, lr=1e-3, monotone_weight=4.0, init_from=str(tmp_path / "base"))
    from semuav_jax.jscc.train import start_params

    for a, b in zip(jax.tree_util.tree_leaves(start), jax.tree_util.tree_leaves(start_params(cfg))):
        np.testing.assert_array_equal(a, b)
    params, hist = train(cfg, photos, out=tmp_path / "a", progress=False, log_every=10)
    assert all(np.isfinite(h[1]) for h in hist)
    train(cfg, photos, out=tmp_path / "b", minutes=1e-9, progress=False, log_every=10)
    resumed, _ = train(cfg, photos, out=tmp_path / "b", resume=True, progress=False, log_every=10)
    for a, b in zip(jax.tree_util.tree_leaves(params), jax.tree_util.tree_leaves(resumed)):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError):
        TrainConfig(monotone_weight=-1.0).validate()


def test_transmit_channels():
    """AWGN: the same noise on the symbols shared by both copies; quantized: noise-free 8-bit I/Q
    of the renormalized prefix with a straight-through (identity) gradient; tails zeroed."""
    from semuav_jax.jscc.train import transmit

    s = power_normalize(_complex(jax.random.PRNGKey(5), (3, M)))
    k = jnp.array([10, 100, 0, 50, 200, M])
    rx = np.asarray(transmit(TrainConfig(snr_db=10.0), s, k, jax.random.PRNGKey(6), copies=2))
    tx = np.asarray(truncate(jnp.tile(s, (2, 1)), k))
    noise = rx - tx
    np.testing.assert_allclose(noise[0, :10], noise[3, :10], atol=1e-6)
    np.testing.assert_allclose(noise[1, :100], noise[4, :100], atol=1e-6)
    assert 0.05 < np.mean(np.abs(noise[5]) ** 2) < 0.15  # variance 10^(-10/10)
    for row, kk in zip(rx, np.asarray(k)):
        assert np.all(row[kk:] == 0)
    q = TrainConfig(channel="quantized")
    rq = np.asarray(transmit(q, s, k[:3], jax.random.PRNGKey(6)))
    np.testing.assert_array_equal(rq, np.asarray(jnp.where(prefix_mask(k[:3]), quantize_iq(truncate(s, k[:3])), 0)))
    w = jax.random.normal(jax.random.PRNGKey(7), s.shape)
    grad = lambda send: jax.grad(lambda re: jnp.sum(w * jnp.real(send(re + 1j * s.imag))))(s.real)
    g_q = grad(lambda x: transmit(q, x, k[:3], jax.random.PRNGKey(6)))
    g_id = grad(lambda x: jnp.where(prefix_mask(k[:3]), truncate(x, k[:3]), 0))
    np.testing.assert_allclose(g_q, g_id, rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match="channel"):
        TrainConfig(channel="rayleigh").validate()


def test_curves_roundtrip_with_metadata(tmp_path):
    C = np.linspace(10, 30, 2 * 5, dtype=np.float32).reshape(2, 5)
    meta = {"image_shape": [32, 32, 3], "ratio": "1/6", "test_images": ["a", "b"]}
    p = save_curves(tmp_path / "c.npz", C, meta)
    cv = load_curves(p)
    np.testing.assert_array_equal(cv.C, C)
    assert cv.meta == {**meta, "M": 4}


def test_bad_curves_files_raise_value_error(tmp_path):
    bad = tmp_path / "bad.npz"
    np.savez(bad, C=np.zeros((3,), np.float32), meta=np.array('{"M": 2}'))
    with pytest.raises(ValueError):
        load_curves(bad)
    corrupt = tmp_path / "corrupt.npz"
    save_curves(tmp_path / "good.npz", np.zeros((2, 5), np.float32), {})
    corrupt.write_bytes((tmp_path / "good.npz").read_bytes()[:200])
    with pytest.raises(ValueError):
        load_curves(corrupt)


def test_bad_inputs_give_clear_errors(tmp_path, capsys):
    with pytest.raises(ValueError, match="no image files"):
        data.folder_photos(tmp_path)
    with pytest.raises(ValueError, match="CIFAR-10"):
        data.cifar10_images(tmp_path)
    (tmp_path / "x.png").write_bytes(b"not a png")
    with pytest.raises(ValueError, match="cannot read"):
        data.folder_photos(tmp_path)
    with pytest.raises(ValueError):
        load_model(tmp_path / "x.png")
    assert main(["curves", "--ckpt", str(tmp_path / "none"), "--out", str(tmp_path / "c.npz")]) == 2
    assert main(["train", "--out", str(tmp_path / "t"), "--steps", "0"]) == 2
    assert "error:" in capsys.readouterr().err


def test_cifar10_loader(tmp_path):
    rng = np.random.default_rng(0)
    for name in ["test_batch"]:
        with open(tmp_path / name, "wb") as f:
            pickle.dump({b"data": rng.integers(0, 256, (7, 3072), dtype=np.uint8)}, f)
    x = data.cifar10_images(tmp_path, test=True)
    assert x.shape == (7, 32, 32, 3) and x.dtype == np.float32 and 0 <= x.min() <= x.max() <= 1


def test_test_set_is_held_out():
    x, names = data.builtin_test_set()
    assert x.shape == (64, 32, 32, 3) and len(set(names)) == 64
    held_out = {n.split(".")[0] for n in data.SKIMAGE_TEST + data.SKLEARN_TEST}
    trained = {n.split(".")[0] for n in data.SKIMAGE_TRAIN + data.SKLEARN_TRAIN}
    assert {n.split("@")[0] for n in names} <= held_out and not held_out & trained


def test_shipped_curves_meet_acceptance():
    cv = load_curves()
    assert cv.M == M == cv.meta["M"] and cv.num_images == cv.meta["num_test_images"] >= 32
    assert np.all(np.isfinite(cv.C))
    mean = cv.C.mean(axis=0)
    span = mean[M] - mean[0]
    assert span >= 12.0
    assert mean[M // 4] - mean[0] >= 0.6 * span
    assert mean[M] >= 27.0
    for key in ("image_shape", "ratio", "bits_per_symbol", "train_snr_db", "dataset", "model_hash"):
        assert key in cv.meta
    assert cv.meta["bits_per_symbol"] == 16
    assert cv.meta["model_hash"] == file_hash(default_model_path())
    net, params = load_model()
    assert isinstance(net, DeepJSCC)


def test_shipped_mean_curve_is_non_decreasing():
    mean = load_curves().C.mean(axis=0)
    assert np.all(mean >= np.maximum.accumulate(mean) - 0.05)


def test_default_train_config_is_the_shipped_recipe():
    meta = load_curves().meta
    assert meta["train_config"] == dataclasses.asdict(TrainConfig())
    assert meta["train_steps_done"] == TrainConfig().steps
