"""The cached references (experiments.references): keyed by everything that makes them, reused only
under the same key, recomputed when the entry is broken; the shipped entry is the default run's at
this code and holds what this code computes."""

import numpy as np
import pytest
from flax import serialization

from semuav_jax.agents.run_config import RunConfig
from semuav_jax.experiments import references as R
from semuav_jax.keys import TEST_SEED, episode_keys


@pytest.fixture
def counted(monkeypatch):
    """references.compute with a count of its calls (the real computation)."""
    calls = []
    real = R.compute

    def compute(*args, **kwargs):
        calls.append(args)
        return real(*args, **kwargs)

    monkeypatch.setattr(R, "compute", compute)
    return calls


def _leaves_equal(a, b):
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for k in a:
            _leaves_equal(a[k], b[k])
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            _leaves_equal(x, y)
    elif isinstance(a, (np.ndarray, np.generic)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    else:
        assert a == b


def test_the_key_holds_what_makes_the_references(params):
    base = R.cache_key(params, [25e3], 4, 4)
    assert R.cache_key(params, [25e3], 4, 4) == base
    for other in (
        R.cache_key(params.replace(B=float(params.B) + 1.0), [25e3], 4, 4),  # any env value
        R.cache_key(params.replace(C=params.C + 1e-3), [25e3], 4, 4),  # the curves
        R.cache_key(params, [20e3], 4, 4),
        R.cache_key(params, [25e3], 5, 4),
        R.cache_key(params, [25e3], 4, 5),
    ):
        assert R.entry_name(other) != R.entry_name(base)


def test_code_hash_follows_the_source(tmp_path, monkeypatch):
    for rel in ("semuav_jax/env.py", "baselines/tsp.py"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("x = 1\n")
    monkeypatch.setattr(R, "_ROOT", tmp_path)
    first = R.code_hash()
    (tmp_path / "baselines/tsp.py").write_text("x = 2\n")
    assert R.code_hash() != first
    (tmp_path / "semuav_jax/agents").mkdir()
    second = R.code_hash()
    (tmp_path / "semuav_jax/agents/network.py").write_text("y = 1\n")  # the agents do not make references
    assert R.code_hash() == second


@pytest.mark.slow
def test_cached_entry_is_reused_only_when_it_parses(params, counted, tmp_path, monkeypatch):
    monkeypatch.setenv("SEMUAV_CACHE", str(tmp_path))
    logged = []
    first = R.references(params, [25e3], 4, 4, workers=1, log=logged.append)
    (entry,) = (tmp_path / "references").iterdir()
    again = R.references(params, [25e3], 4, 4, workers=1, log=logged.append)
    assert len(counted) == 1 and "cached" in logged[-1]
    _leaves_equal(R.packable(first), again)
    entry.write_bytes(entry.read_bytes()[:100])  # truncated: recomputed, never trusted
    R.references(params, [25e3], 4, 4, workers=1, log=logged.append)
    assert len(counted) == 2
    blob = serialization.msgpack_restore(entry.read_bytes())
    assert blob["key"] == R.cache_key(params, [25e3], 4, 4)
    monkeypatch.setenv("SEMUAV_CACHE", "off")
    entry.unlink()
    R.references(params, [25e3], 4, 4, workers=1, log=logged.append)
    assert len(counted) == 3 and not entry.exists()


def _default():
    cfg = RunConfig.from_preset("default", command="")
    params = cfg.env_params()
    return cfg, params, (params, R.bandwidths_of(cfg.agent, params), cfg.eval_episodes, cfg.validation_episodes)


def test_the_shipped_entry_is_the_default_runs_at_this_code():
    """Fails when the core or the baselines change: regenerate it with
    ``python -m semuav_jax.experiments.references`` (about 20 min)."""
    _, _, args = _default()
    shipped = sorted(R.SHIPPED.glob("*.msgpack"))
    assert [p.name for p in shipped] == [R.entry_name(R.cache_key(*args))], (
        "semuav_jax/data/references is stale: run python -m semuav_jax.experiments.references"
    )


@pytest.mark.slow
def test_the_shipped_flights_are_what_this_code_flies():
    """The shipped flights on the first 40 test layouts at 25 kHz, flown again with the shipped knobs."""
    from baselines.report import flights

    cfg, params, args = _default()
    entry = R._load(R.SHIPPED / R.entry_name(R.cache_key(*args)), R.cache_key(*args))
    assert entry is not None
    j = list(args[1]).index(25e3)
    per_b = {"v_star", "knobs", "switch"}  # the tuning's lists with one entry per bandwidth
    at_j = {
        n: {f: [x[j]] if f in per_b else x for f, x in v.items()} if isinstance(v, dict) else v
        for n, v in entry["tuning"].items()
    }
    (row,) = flights(params, episode_keys(TEST_SEED, cfg.eval_episodes)[:40], at_j, [25e3], workers=2)
    for name, m in row.items():
        shipped = entry["flights"][j][name]
        np.testing.assert_array_equal(m["arrived"], shipped["arrived"][:40], err_msg=name)
        np.testing.assert_allclose(m["mean_psnr"], shipped["mean_psnr"][:40], atol=1e-3, err_msg=name)


def test_search_reads_the_cached_flights_at_the_same_knobs():
    """semuav-search takes TSP-dwell, dwell-switch and the exact planner from the cache when the
    run's eval.json was written from it (same counts, same tuning), a prefix for fewer layouts."""
    import copy
    import json

    from semuav_jax.experiments.search import VERSUS, _cached_flights

    cfg, params, args = _default()
    saved = json.loads((R.SHIPPED.parent / "agent" / "eval.json").read_text())
    entry = R.lookup(*args)
    got = _cached_flights(params, saved, 100)
    assert sorted(got) == [float(b) for b in args[1]]
    for j, b in enumerate(args[1]):
        assert sorted(got[float(b)]) == sorted(VERSUS[1:])
        for name, m in got[float(b)].items():
            np.testing.assert_array_equal(m["mean_psnr"], np.asarray(entry["flights"][j][name]["mean_psnr"])[:100])
            assert (
                abs(
                    float(np.mean(entry["flights"][j][name]["mean_psnr"]))
                    - saved["rows"][j]["references"][name]["mean_psnr"]
                )
                < 1e-4
            )
    assert _cached_flights(params, saved, cfg.eval_episodes + 1) is None  # more layouts than cached
    other = copy.deepcopy(saved)
    other["tuning"]["tsp-dwell"]["knobs"][0][1] += 8.0  # other knobs: not these flights
    assert _cached_flights(params, other, 100) is None
    assert _cached_flights(params.replace(B=float(params.B) + 1.0), saved, 100) is None  # another env
