"""Run folders, the one format for a trained agent (docs/ddqn.md, "Run folder"): ``config.json``
(how it was trained: scenario, seeds, the command, the DDQNConfig), ``model.msgpack`` (the
weights of every seed, leading seed axis), ``checkpoint.msgpack`` (the whole training state while
it runs), ``metrics.csv`` (per-chunk training metrics), ``eval.json`` / ``eval.md`` (the comparison
with the references). ``train.py`` writes them; ``eval.py`` and the shipped agent read them."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

from flax import serialization

from semuav_jax.agents.ddqn import DDQNConfig

CONFIG_FILE, METRICS_FILE, CKPT_FILE, MODEL_FILE = "config.json", "metrics.csv", "checkpoint.msgpack", "model.msgpack"
EVAL_FILE, EVAL_MD = "eval.json", "eval.md"
CURVE_FILE = "learning_curve.png"
RUN_FILES = (CONFIG_FILE, METRICS_FILE, CKPT_FILE, MODEL_FILE, EVAL_FILE, EVAL_MD, CURVE_FILE)  # all a run writes
SHIPPED = "agent"  # the shipped run folder, semuav_jax/data/agent: the output of ``python train.py``


def clear_run(folder) -> None:
    """Delete a run folder's files (``RUN_FILES`` and their leftover temporary files); ValueError,
    deleting nothing, if it holds anything else."""
    from semuav_jax.io import remove_stale_temps

    folder = Path(folder)
    remove_stale_temps(folder, RUN_FILES)
    foreign = sorted(p.name for p in folder.iterdir() if p.name not in RUN_FILES)
    if foreign:
        raise ValueError(
            f"{folder} holds files that are not a run's ({', '.join(foreign)}); "
            "refusing to overwrite it: choose another --out"
        )
    for name in RUN_FILES:
        (folder / name).unlink(missing_ok=True)


def finished(folder) -> bool:
    folder = Path(folder)
    return (folder / CONFIG_FILE).is_file() and (folder / MODEL_FILE).is_file()


def check_weights(run: dict, weights, where, seeds: int | None = None) -> None:
    """ValueError (one line) unless ``weights`` are finite arrays with the shapes of the Q-network
    of ``run`` (config.json's scenario and 'ddqn' block), with a leading axis of ``seeds`` when given."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from semuav_jax.agents.ddqn import input_size, q_network

    config = ddqn_config(run, where)
    try:
        params = run_params(run)
    except (ValueError, TypeError, KeyError, FileNotFoundError) as e:
        raise ValueError(f"{where}: its run description does not build its scenario ({e})") from None
    net = q_network(params, config)
    want = jax.eval_shape(net.init, jax.random.key(0), jnp.zeros((input_size(params, config),), jnp.float32))
    lead = () if seeds is None else (seeds,)
    shapes = lambda tree: {
        "/".join(str(getattr(k, "key", k)) for k in path): np.shape(x)
        for path, x in jax.tree_util.tree_flatten_with_path(tree)[0]
    }
    got, want = shapes(weights), {k: lead + v for k, v in shapes(want).items()}
    if got != want:
        bad = [f"{k} {got.get(k, 'missing')} (expected {want[k]})" for k in want if got.get(k) != want[k]]
        bad += [f"{k} (not a layer of it)" for k in got if k not in want]
        raise ValueError(
            f"{where}: its weights do not match its config (hidden {list(config.hidden)}, "
            f"{net.num_actions} actions): {', '.join(bad[:3])}"
        )
    if not all(np.issubdtype(np.asarray(w).dtype, np.floating) for w in jax.tree.leaves(weights)):
        raise ValueError(f"{where}: its weights are not float arrays")
    if not all(np.isfinite(np.asarray(w)).all() for w in jax.tree.leaves(weights)):
        raise ValueError(f"{where}: its weights are not finite (NaN or inf: the training diverged)")


def load_run(folder):
    """(run description, DDQNConfig, weights with a leading seed axis) of a finished run folder,
    its weights checked against its config and finite."""
    folder = Path(folder)
    if not finished(folder):
        raise ValueError(f"{folder} is not a finished train.py run (needs {CONFIG_FILE} and {MODEL_FILE})")
    try:
        run = json.loads((folder / CONFIG_FILE).read_text())
    except ValueError as e:
        raise ValueError(f"{folder / CONFIG_FILE} is not a train.py run config ({e})") from None
    config = ddqn_config(run, folder / CONFIG_FILE)
    try:
        nets = serialization.msgpack_restore((folder / MODEL_FILE).read_bytes())
    except Exception as e:  # noqa: BLE001 - msgpack raises any kind for a file that is not one
        raise ValueError(f"{folder / MODEL_FILE} is not a weights file ({type(e).__name__})") from None
    seeds = run.get("seeds") if isinstance(run, dict) else None
    check_weights(
        run, nets, folder / MODEL_FILE, seeds if isinstance(seeds, int) and not isinstance(seeds, bool) else None
    )
    return run, config, nets


def ddqn_config(run, where) -> DDQNConfig:
    """The DDQNConfig of a run description (config.json at ``where``); ValueError (one line) if it
    has no 'ddqn' block or the block has a key DDQNConfig does not know."""
    import dataclasses

    if not isinstance(run, dict) or not isinstance(run.get("ddqn"), dict):
        raise ValueError(f"{where} has no 'ddqn' block")
    unknown = sorted(set(run["ddqn"]) - {f.name for f in dataclasses.fields(DDQNConfig)})
    if unknown:
        raise ValueError(f"{where}: unknown key{'s' * (len(unknown) > 1)} in its 'ddqn' block: {', '.join(unknown)}")
    try:
        return DDQNConfig.from_dict(run["ddqn"])
    except TypeError as e:
        raise ValueError(f"{where}: bad 'ddqn' block ({e})") from None


def run_params(run: dict):
    """The EnvParams a run was trained with, from its description (config.json): scenario, curves
    (a file, 'synthetic', or None for the shipped ones), reward mode, B, kappa_c, r_g."""
    from semuav_jax.agents.scenarios import scenario_params
    from semuav_jax.curves import load_curves, synthetic_curves

    source = run.get("curves")
    curves = synthetic_curves() if source == "synthetic" else load_curves(source) if source else None
    return scenario_params(
        run["scenario"],
        curves,
        reward_mode=run["reward_mode"],
        B=run["bandwidth"],
        kappa_c=run["kappa_c"],
        r_g=run.get("r_g", 500.0),
    )


def shipped_folder() -> Path:
    return Path(str(resources.files("semuav_jax") / "data" / SHIPPED))


def load_shipped():
    """The shipped agent: :func:`load_run` of ``semuav_jax/data/agent``."""
    return load_run(shipped_folder())
