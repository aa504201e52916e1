"""The references the learned controller is compared with (docs/ddqn.md, "Results"), cached: their
knobs tuned on validation layouts and their flights on the test layouts do not depend on the agent,
so ``train.py``'s evaluation and ``semuav-compare`` reuse them. An entry is keyed by everything that
makes it: the env parameters (curves included), the layouts, the bandwidths, the source of the core
and the baselines (sha256) and the versions of JAX, NumPy and OR-Tools; any change recomputes it.
Entries are looked up in the package (``semuav_jax/data/references``: the default run's, written by
``python -m semuav_jax.experiments.references``) and in the user's cache folder
(``$XDG_CACHE_HOME/semuav-jax``, or ``$SEMUAV_CACHE``; ``SEMUAV_CACHE=off`` turns it off)."""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time
from collections.abc import Callable, Sequence
from importlib import metadata
from pathlib import Path

import jax
import numpy as np
from flax import serialization

from baselines.report import BANDWIDTHS, flights, tune
from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.run_config import RunConfig
from semuav_jax.distributed import is_main
from semuav_jax.experiments.fig2 import shared_plans
from semuav_jax.experiments.stages import packable
from semuav_jax.io import atomic_write
from semuav_jax.keys import TEST_SEED, VALIDATION_SEED, episode_keys
from semuav_jax.params import EnvParams
from semuav_jax.sharding import agree

FORMAT = "semuav-jax references 1"  # a new one when ``compute`` changes (its callees are in SOURCES)
SHIPPED = Path(__file__).resolve().parents[1] / "data" / "references"
_ROOT = Path(__file__).resolve().parents[2]
# what the references run: the core, the baselines and fig2's planning split over processes
SOURCES = ("semuav_jax/*.py", "semuav_jax/jscc/*.py", "baselines/*.py", "semuav_jax/experiments/fig2.py")


def bandwidths_of(config: DDQNConfig, params: EnvParams) -> tuple[float, ...]:
    """The bandwidths a run is evaluated at: ``BANDWIDTHS`` for an agent trained over a range of B,
    else its env's B."""
    return tuple(BANDWIDTHS) if config.bandwidth_range is not None else (float(params.B),)


def code_hash() -> str:
    """sha256 over the source files the references run (paths and bytes, sorted)."""
    h = hashlib.sha256()
    for path in sorted(p for pattern in SOURCES for p in _ROOT.glob(pattern)):
        h.update(path.relative_to(_ROOT).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def params_hash(params: EnvParams) -> str:
    """sha256 of every leaf of ``params`` (dtype, shape, bytes) and of its structure."""
    leaves, treedef = jax.tree.flatten(params)
    h = hashlib.sha256(str(treedef).encode())
    for leaf in leaves:
        a = np.ascontiguousarray(np.asarray(leaf))
        h.update(f"{a.dtype}{a.shape}".encode() + a.tobytes())
    return h.hexdigest()


def cache_key(params: EnvParams, bandwidths: Sequence[float], episodes: int, validation_episodes: int) -> dict:
    return {
        "format": FORMAT,
        "params_sha256": params_hash(params),
        "bandwidths": [float(b) for b in bandwidths],
        "episodes": episodes,
        "test_seed": TEST_SEED,
        "validation_episodes": validation_episodes,
        "validation_seed": VALIDATION_SEED,
        "code_sha256": code_hash(),
        "versions": {name: metadata.version(name) for name in ("jax", "jaxlib", "numpy", "ortools")},
    }


def entry_name(key: dict) -> str:
    return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:20] + ".msgpack"


def user_cache() -> Path | None:
    """The user's cache folder of references, or None when ``SEMUAV_CACHE=off``."""
    given = os.environ.get("SEMUAV_CACHE")
    if given == "off":
        return None
    base = Path(given) if given else Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "semuav-jax"
    return base / "references"


def _load(path: Path, key: dict) -> dict | None:
    """The entry at ``path`` when it parses and holds ``key``; else None (a broken file is recomputed)."""
    if not path.is_file():
        return None
    try:
        blob = serialization.msgpack_restore(path.read_bytes())
    except Exception:  # noqa: BLE001 - a truncated or crafted file raises anything: recompute it
        return None
    ok = isinstance(blob, dict) and blob.get("key") == json.loads(json.dumps(key))
    return blob["value"] if ok and isinstance(blob.get("value"), dict) else None


def _save(path: Path, key: dict, value: dict) -> Path:
    return atomic_write(path, serialization.msgpack_serialize({"key": key, "value": packable(value)}))


def compute(
    params: EnvParams,
    bandwidths: Sequence[float],
    episodes: int,
    validation_episodes: int,
    workers: int,
    log: Callable[[str], None] = print,
) -> dict:
    """{"tuning": knobs chosen on validation layouts, "flights": per bandwidth, per reference, the
    per-episode metrics on the test layouts} (``baselines.report.tune`` and ``flights``)."""
    t0 = time.time()
    log(f"references: tuning every rule on {validation_episodes} validation layouts")
    tuned = tune(params, bandwidths, validation_episodes, workers=workers)
    log(f"references: tuned in {time.time() - t0:.0f} s; planning {episodes} test layouts")
    keys = episode_keys(TEST_SEED, episodes)
    plans = [shared_plans(keys, params.replace(B=b), workers) for b in bandwidths]  # each process plans its share
    log(f"references: planned at {time.time() - t0:.0f} s; flying every reference at {len(bandwidths)} bandwidths")
    out = {"tuning": tuned, "flights": flights(params, keys, tuned, bandwidths, workers, plans=plans)}
    log(f"references: done in {time.time() - t0:.0f} s")
    return out


def lookup(params: EnvParams, bandwidths: Sequence[float], episodes: int, validation_episodes: int) -> dict | None:
    """The shipped or the user's cached entry of this key, or None unless every process holds it."""
    key = cache_key(params, bandwidths, episodes, validation_episodes)
    name, folder = entry_name(key), user_cache()
    places = [SHIPPED / name] + ([folder / name] if folder is not None else [])
    found = next((v for v in (_load(p, key) for p in places) if v is not None), None)
    return found if agree(found is not None) else None


def references(
    params: EnvParams,
    bandwidths: Sequence[float],
    episodes: int,
    validation_episodes: int,
    workers: int = 2,
    log: Callable[[str], None] = print,
    cache: bool = True,
) -> dict:
    """:func:`compute`'s result, read from the shipped or the user's cache when an entry holds this
    key, else computed (and saved in the user's cache)."""
    found = lookup(params, bandwidths, episodes, validation_episodes) if cache else None
    if found is not None:
        log("references: cached (same env, layouts, bandwidths and code)")
        return found
    out = compute(params, bandwidths, episodes, validation_episodes, workers, log)
    folder = user_cache() if cache else None
    if folder is not None and is_main():
        key = cache_key(params, bandwidths, episodes, validation_episodes)
        try:
            _save(folder / entry_name(key), key, out)
        except OSError as e:  # a read-only home: the result stands, it is only not kept
            log(f"references: not cached ({e})")
    return out


def main(argv: list[str] | None = None) -> int:
    """Write the default run's entry into the package: ``python -m semuav_jax.experiments.references``."""
    ap = argparse.ArgumentParser(description="Recompute the shipped references of the default run (about 20 min).")
    ap.parse_args(argv)
    cfg = RunConfig.from_preset("default", command="")
    params = cfg.env_params()
    args = (params, bandwidths_of(cfg.agent, params), cfg.eval_episodes, cfg.validation_episodes)
    key = cache_key(*args)
    out = compute(*args, workers=cfg.workers)
    path = _save(SHIPPED / entry_name(key), key, out)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB)")
    for old in SHIPPED.glob("*.msgpack"):
        if old != path:
            old.unlink()
            print(f"removed the stale {old.name}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
