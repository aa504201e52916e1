"""Sharding primitives on several processes of one run (jax.distributed over loopback) and block-wise episode bits."""

import json
import textwrap

import pytest
from multiprocess import run

PRIMITIVES = textwrap.dedent(
    """
    import argparse, json
    from semuav_jax import distributed
    p = argparse.ArgumentParser()
    distributed.add_options(p)
    distributed.initialize(p.parse_args())
    import jax, numpy as np
    from semuav_jax.sharding import agree, gather, map_episodes, shard_episodes, split_hosts
    keys = jax.random.split(jax.random.PRNGKey(3), 7)
    draw = jax.jit(jax.vmap(lambda k: jax.random.uniform(k, (3,))))
    sharded = shard_episodes(keys)
    u = gather(draw(sharded))
    m = map_episodes(lambda k: {"u": draw(k).T, "rows": k.shape[0] + 0 * k[:, 0]}, keys)
    owner = split_hosts(lambda lo, hi: {"i": np.arange(lo, hi), "p": np.full(hi - lo, jax.process_index())}, 7)
    r = {"process": jax.process_index(), "processes": jax.process_count(), "devices": jax.device_count()}
    r["padded"] = int(sharded.shape[0])
    r["local_rows"] = sum(s.data.shape[0] for s in sharded.addressable_shards)
    r["same"] = bool(np.array_equal(u[:7], np.asarray(jax.vmap(lambda k: jax.random.uniform(k, (3,)))(keys))))
    r["padding_repeats_last"] = bool(np.array_equal(u[7:], np.repeat(u[6:7], len(u) - 7, 0)))
    r["blocks_same"], r["block_rows"] = bool(np.array_equal(m["u"], u[:7].T)), m["rows"].tolist()
    r["index"], r["owner"] = owner["i"].tolist(), owner["p"].tolist()
    r["all_true"], r["only_0"] = agree(True), agree(jax.process_index() == 0)
    print(json.dumps(r))
    """
)


@pytest.mark.parametrize("devices", [1, 2])
def test_two_processes_shard_gather_and_split_work(devices):
    codes, texts = run(["-c", PRIMITIVES], 2, limit_s=120, devices=devices)
    assert codes == [0, 0], [t[1][-2000:] for t in texts]
    for i, (out, _) in enumerate(texts):
        r = json.loads(out.strip().splitlines()[-1])
        assert r["process"] == i and r["processes"] == 2 and r["devices"] == 2 * devices
        assert r["padded"] == 8 and r["local_rows"] == 4  # 7 episodes padded to 8, half in each process
        assert r["same"] and r["padding_repeats_last"]  # the keys' draws do not depend on the split
        # fixed-size blocks (episode axis last here): fn sees one block of 7 episodes at a time
        assert r["blocks_same"] and r["block_rows"] == [7] * 7
        assert r["index"] == list(range(7)) and r["owner"] == [0, 0, 0, 0, 1, 1, 1]
        assert r["all_true"] is True and r["only_0"] is False


@pytest.mark.slow
def test_an_episode_s_bits_depend_on_its_block_only(params):
    """map_episodes (one process, one device): the first 64 of 70 episodes (blocks of 64) are the
    bits of a batch of those 64; the episode axis may be first or last."""
    import jax
    import numpy as np

    from baselines import sweep
    from semuav_jax.sharding import BLOCK, map_episodes

    keys = jax.random.split(jax.random.PRNGKey(5), BLOCK + 6)
    m = sweep("greedy", keys, params, v_b=(8.9, 14.0))  # (B, v_b, E): episode axis last
    m_block = sweep("greedy", keys[:BLOCK], params, v_b=(8.9, 14.0))
    assert m["mean_psnr"].shape == (1, 2, BLOCK + 6) and np.ptp(m["mean_psnr"]) > 0
    for k in m_block:
        np.testing.assert_array_equal(m[k][..., :BLOCK], m_block[k], err_msg=k)
    draw = jax.jit(jax.vmap(lambda k: jax.random.uniform(k, (3,))))
    np.testing.assert_array_equal(map_episodes(draw, keys, axis=0), np.asarray(draw(keys)))
