"""Resumable sweep items (docs/scaling.md): a grid of ``make_params`` overrides x policies x seeds.

A grid (JSON or TOML) holds ``episodes``, ``seeds``, ``policies`` and ``params`` (each value a
scalar, or a list: one grid axis), optionally ``scenario`` (random or fixed) and ``curves``. A
policy is a baseline name (``greedy``, ``tsp``, ...), optionally at a speed (``greedy@17``), a
``train.py`` run folder (``RUN``, or ``RUN#s`` for its training seed s), or ``shipped``.

An item is one (grid point, policy, seed): ``episodes`` episodes in one jitted, vmapped program
(traced parameters: the points of one shape share it), keys ``split(fold_in(PRNGKey(seed),
point id), episodes)`` with the point id taken from the overrides' text, so every policy of a
point flies the same episodes, whatever the grid's order or split. Each item is written once to
``OUT/items/<hash>.json``, named by the hash of everything that defines it.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import tomllib
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from baselines.evaluate import baseline_metrics, resolve, tsp_ranks
from baselines.policies import DEFAULT_V_B, POLICIES
from semuav_jax.agents.network import q_network
from semuav_jax.agents.policy import greedy_policy, initial_state
from semuav_jax.agents.runs import MODEL_FILE, load_run, shipped_folder
from semuav_jax.agents.scenarios import scenario_params
from semuav_jax.curves import load_curves
from semuav_jax.io import atomic_write
from semuav_jax.params import EnvParams
from semuav_jax.provenance import file_hash
from semuav_jax.rollout import rollout
from semuav_jax.sharding import map_episodes
from semuav_jax.stats import mean_ci, wilson_interval

KEYS = ("episodes", "seeds", "policies", "params", "scenario", "curves")


def load_grid(path: str | os.PathLike) -> dict:
    """The grid of a JSON or TOML file, checked (ValueError, one line)."""
    path = Path(path)
    try:
        text = path.read_text()
        grid = tomllib.loads(text) if path.suffix == ".toml" else json.loads(text)
    except (OSError, ValueError) as e:
        raise ValueError(f"cannot read the grid {path}: {e}") from None
    unknown = set(grid) - set(KEYS)
    if unknown:
        raise ValueError(f"{path}: unknown grid key(s) {sorted(unknown)}; the keys are {list(KEYS)}")
    grid = {"scenario": "random", "curves": None, "params": {}, **grid}
    if not isinstance(grid.get("episodes"), int) or grid["episodes"] < 1:
        raise ValueError(f"{path}: 'episodes' must be an integer >= 1")
    grid["seeds"] = [grid["seeds"]] if isinstance(grid.get("seeds"), int) else grid.get("seeds")
    if not grid["seeds"] or not all(isinstance(s, int) and s >= 0 for s in grid["seeds"]):
        raise ValueError(f"{path}: 'seeds' must be an integer >= 0 or a list of them")
    if not grid.get("policies") or not all(isinstance(p, str) for p in grid["policies"]):
        raise ValueError(f"{path}: 'policies' must be a list of baseline names or run folders")
    for p in grid["policies"]:
        policy_spec(p)
    return grid


def policy_spec(text: str) -> dict:
    """A policy of the grid: {'baseline': name, 'v_b': speed} or {'run': folder, 'seed': s}."""
    name, _, speed = text.partition("@")
    if name in POLICIES:
        try:
            v = float(speed) if speed else DEFAULT_V_B
        except ValueError:
            raise ValueError(f"policy {text!r}: the speed after @ must be a number in m/s") from None
        if not np.isfinite(v) or v <= 0:
            raise ValueError(f"policy {text!r}: the speed must be finite and > 0 m/s")
        return {"baseline": name, "v_b": v}
    folder, _, seed = text.partition("#")
    folder = shipped_folder() if folder == "shipped" else Path(folder)
    if not (folder / MODEL_FILE).is_file():
        raise ValueError(
            f"policy {text!r} is neither a baseline ({', '.join(sorted(POLICIES))}) nor a finished train.py run folder"
        )
    if seed and not seed.isdigit():
        raise ValueError(f"policy {text!r}: the training seed after # must be an integer")
    return {"run": str(folder.resolve()), "seed": int(seed or 0), "weights_sha256": file_hash(folder / MODEL_FILE)}


def points(grid: dict) -> list[dict]:
    """Every combination of the ``params`` axes (lists), in the file's order."""
    axes = {k: v if isinstance(v, list) else [v] for k, v in grid["params"].items()}
    return [dict(zip(axes, combo)) for combo in itertools.product(*axes.values())]


def items(grid: dict) -> list[dict]:
    """The grid's items: points x policies x seeds, each with its file name (``hash``)."""
    curves = None if grid["curves"] is None else file_hash(grid["curves"])
    out = []
    for point, policy, seed in itertools.product(points(grid), grid["policies"], grid["seeds"]):
        item = {
            "point": point,
            "policy": policy,
            "spec": policy_spec(policy),
            "seed": seed,
            "episodes": grid["episodes"],
            "scenario": grid["scenario"],
            "curves_file_sha256": curves,
        }
        item["hash"] = hashlib.sha256(_canonical(item).encode()).hexdigest()[:20]
        out.append(item)
    return out


def _canonical(x: Any) -> str:
    return json.dumps(x, sort_keys=True, separators=(",", ":"))


def point_keys(point: dict, seed: int, episodes: int) -> jax.Array:
    """The episodes' keys of a grid point and seed (independent of the grid's order and split)."""
    point_id = int(hashlib.sha256(_canonical(point).encode()).hexdigest()[:8], 16) & 0x7FFFFFFF
    return jax.random.split(jax.random.fold_in(jax.random.PRNGKey(seed), point_id), episodes)


def item_path(out: str | os.PathLike, item: dict) -> Path:
    return Path(out) / "items" / f"{item['hash']}.json"


def item_params(grid: dict, item: dict) -> EnvParams:
    try:
        return scenario_params(
            grid["scenario"], load_curves(grid["curves"]) if grid["curves"] else None, **item["point"]
        )
    except (TypeError, ValueError) as e:
        raise ValueError(f"grid point {item['point']}: {e}") from None


def run_item(grid: dict, item: dict) -> dict:
    """Per-episode metrics (lists) of one item, its episodes sharded over every device of every process."""
    params = item_params(grid, item)
    keys = point_keys(item["point"], item["seed"], item["episodes"])
    spec = item["spec"]
    if "baseline" in spec:
        rank = (
            tsp_ranks(keys, params)
            if spec["baseline"] == "tsp"
            else np.broadcast_to(np.arange(params.N, dtype=np.int32), (len(keys), params.N))
        )
        policy, v_b = resolve(spec["baseline"]), jnp.float32(spec["v_b"])
        m = map_episodes(lambda part: _baseline(policy, part[0], params, v_b, part[1]), (keys, jnp.asarray(rank)))
    else:
        run, nets = load_run(spec["run"])
        config = run.agent
        if spec["seed"] >= len(jax.tree.leaves(nets)[0]):
            raise ValueError(f"policy {item['policy']!r}: the run has {len(jax.tree.leaves(nets)[0])} training seeds")
        net = jax.tree.map(lambda x: jnp.asarray(x[spec["seed"]]), nets)
        policy = greedy_policy(q_network(params, config), config)
        m = map_episodes(lambda k: rollout(policy, k, params, initial_state(net, config), state_axes=None)[0], keys)
    if not np.all(m.pop("valid")):
        raise ValueError(f"item {item['hash']}: the simulation left float32 at {item['point']}")
    return {k: v.tolist() for k, v in m.items()}


_baseline = jax.jit(baseline_metrics, static_argnums=0)


def save_item(out: str | os.PathLike, item: dict, metrics: dict) -> Path:
    record = {k: v for k, v in item.items() if k != "hash"} | {"hash": item["hash"], "metrics": metrics}
    return atomic_write(item_path(out, item), json.dumps(record).encode())


def merge(out: str | os.PathLike, its: list[dict]) -> dict:
    """The table of the items (all done): per grid point and policy, the episodes of every seed
    pooled: mean PSNR with its t interval, arrival with its Wilson interval, coverage."""
    missing = [it for it in its if not item_path(out, it).is_file()]
    if missing:
        raise ValueError(
            f"{len(missing)} of {len(its)} items are not done (first: {missing[0]['hash']}); run them before --merge"
        )
    groups: dict = {}
    for it in its:
        m = json.loads(item_path(out, it).read_text())["metrics"]
        g = groups.setdefault(
            _canonical([it["point"], it["policy"]]),
            {"point": it["point"], "policy": it["policy"], "seeds": [], "m": {}},
        )
        g["seeds"].append(it["seed"])
        for k, v in m.items():
            g["m"].setdefault(k, []).extend(v)
    rows = []
    for g in groups.values():
        psnr, ci = mean_ci(g["m"]["mean_psnr"])
        arrived = np.asarray(g["m"]["arrived"], np.float64)
        lo, hi = wilson_interval(arrived.mean(), arrived.size)
        rows.append(
            {
                **g["point"],
                "policy": g["policy"],
                "seeds": len(g["seeds"]),
                "episodes": arrived.size,
                "mean_psnr": psnr,
                "ci95": ci,
                "arrived": float(arrived.mean()),
                "arrived_lo": float(lo),
                "arrived_hi": float(hi),
                "coverage": float(np.mean(g["m"]["coverage"])),
                "mission_time": float(np.mean(g["m"]["mission_time"])),
            }
        )
    return {"rows": rows, "items": len(its)}


def table_csv(table: dict) -> str:
    import csv
    import io

    text = io.StringIO()
    w = csv.DictWriter(text, list(table["rows"][0]), lineterminator="\n")
    w.writeheader()
    w.writerows(table["rows"])
    return text.getvalue()
