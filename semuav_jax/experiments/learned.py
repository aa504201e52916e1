"""The learned controller against the strongest references (docs/ddqn.md, "Results").

Every training seed is evaluated greedily on the same test layouts (``keys.TEST_SEED``) as greedy
and TSP at the paper's 8.9 m/s and at their tuned speed v_b*, the dwell rules at their tuned knobs
(chosen on ``keys.VALIDATION_SEED`` layouts, ``baselines.report.tune``), dwell-switch, the planners
and plan-switch, at each bandwidth. Margins are
per-episode paired differences; the statistic across seeds is the mean of the seeds' means with
its t interval. No seed is selected: every one is reported.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from baselines.report import BANDWIDTHS, best_arriving, reference_summary, summary, tune
from baselines.report_table import reference_line
from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.demos import EXPERT, expert_k
from semuav_jax.agents.evaluate import expert_metrics, seed_metrics
from semuav_jax.agents.network import q_network
from semuav_jax.distributed import is_main
from semuav_jax.experiments.references import bandwidths_of, references
from semuav_jax.keys import TEST_SEED, VALIDATION_SEED, episode_keys
from semuav_jax.params import EnvParams
from semuav_jax.stats import mean_ci, pm, wilson_interval

if TYPE_CHECKING:
    from semuav_jax.agents.network import QNetwork
    from semuav_jax.runfolder import RunFolder

REFERENCES = (
    "greedy v_b*",
    "tsp v_b*",
    "greedy-dwell",
    "tsp-dwell",
)  # the fixed rules, tuned: margins that must be positive
MARGINS = (
    "greedy 8.9",
    "tsp 8.9",
    *REFERENCES,
    "dwell-switch",
    "planner",
    "exact planner",
    "plan-switch",
)  # every reference the agent is compared with, paired


def _header(names: Iterable[str]) -> str:
    return " | ".join(f"− {n.replace('tsp', 'TSP')}" for n in names)


def compare(
    network: QNetwork,
    nets: Any,
    config: DDQNConfig,
    params: EnvParams,
    bandwidths: Sequence[float] = BANDWIDTHS,
    episodes: int = 1000,
    validation_episodes: int = 500,
    workers: int = 2,
    ablate_shield: bool = True,
    log: Callable[[str], None] = print,
    cache: bool = True,
) -> dict:
    """Every number of the table of docs/ddqn.md (JSON-ready) for the seeds ``nets`` of one agent;
    the references from ``experiments.references`` (cached unless ``cache`` is False)."""
    refs = references(params, bandwidths, episodes, validation_episodes, workers, log=log, cache=cache)
    tuned, refs = refs["tuning"], refs["flights"]
    log("v_b* on validation layouts: " + ", ".join(f"{n} {tuned[n]['v_star']}" for n in ("greedy", "tsp")))
    keys = episode_keys(TEST_SEED, episodes)
    unshielded = dataclasses.replace(config, shield_margin=None)
    per_seed = seed_metrics(network, nets, config, keys, params, bandwidths)
    expert = expert_metrics(config, keys, params, bandwidths) if config.demo_steps else None
    margins = MARGINS + ((EXPERT,) if expert else ())
    if ablate_shield and config.shield_margin is not None:
        bare = seed_metrics(network, nets, unshielded, keys, params, bandwidths)
    seeds = per_seed["mean_psnr"].shape[0]
    rows = []
    for j, (b, ref) in enumerate(zip(bandwidths, refs)):
        agent = [{k: v[s, j] for k, v in per_seed.items()} for s in range(seeds)]
        row = {"B": float(b), "references": {k: reference_summary(m) for k, m in ref.items()}, "seeds": []}
        if expert:
            ref = {**ref, EXPERT: {k: v[j] for k, v in expert.items()}}
            row["expert"] = {"k": float(np.asarray(expert_k(b, config))), **summary(ref[EXPERT])}
        for m in agent:
            s = {**summary(m), "shield_share": float(np.mean(m["shield_share"]))}
            for name in margins:
                s[f"minus {name}"] = mean_ci(m["mean_psnr"] - ref[name]["mean_psnr"])
            row["seeds"].append(s)
        if ablate_shield and config.shield_margin is not None:
            for i, s in enumerate(row["seeds"]):
                s["arrived_without_shield"] = float(np.mean(bare["arrived"][i, j]))
                s["mean_psnr_without_shield"] = float(np.mean(bare["mean_psnr"][i, j]))
        means = [s["mean_psnr"] for s in row["seeds"]]
        row["agent"] = {"mean_psnr": mean_ci(means)}
        for name in margins:
            row["agent"][f"minus {name}"] = mean_ci([s[f"minus {name}"][0] for s in row["seeds"]])
        arrived = np.concatenate([np.asarray(m["arrived"], np.float64) for m in agent])
        row["agent"]["arrived"] = float(arrived.mean())
        row["agent"]["arrived_wilson95"] = [float(x) for x in wilson_interval(arrived.mean(), arrived.size)]
        row["agent"]["shield_share"] = float(np.mean([s["shield_share"] for s in row["seeds"]]))
        rows.append(row)
        a = row["agent"]
        log(
            f"B = {b / 1e3:g} kHz: agent {a['mean_psnr'][0]:.2f} {pm(a['mean_psnr'][1])} dB over "
            f"{len(means)} seeds ({', '.join(f'{x:.2f}' for x in means)}); "
            + ", ".join(f"{n} {a['minus ' + n][0]:+.2f} {pm(a['minus ' + n][1])}" for n in margins)
        )
    return {
        "episodes": episodes,
        "test_seed": TEST_SEED,
        "validation_seed": VALIDATION_SEED,
        "validation_episodes": validation_episodes,
        "tuning": tuned,
        "margins": list(margins),
        "rows": rows,
    }


def markdown(r: dict) -> str:
    """The tables of docs/ddqn.md: the agent per seed and across seeds against the references."""
    margins = r.get("margins", MARGINS)
    lines = [
        f"{r['episodes']} test layouts (seed {r['test_seed']}), never used in training or selection; "
        f"v_b* from {r['validation_episodes']} validation layouts (seed {r['validation_seed']}).",
        "",
        f"| B (kHz) | agent, mean of seeds (dB) | {_header(margins)} | arrival | shield share |",
        "|---" * (4 + len(margins)) + "|",
    ]
    for row in r["rows"]:
        a = row["agent"]
        cells = [f"{a[f'minus {n}'][0]:+.2f} {pm(a[f'minus {n}'][1])}" for n in margins]
        lines.append(
            f"| {row['B'] / 1e3:g} | {a['mean_psnr'][0]:.2f} {pm(a['mean_psnr'][1])} | "
            + " | ".join(cells)
            + f" | {100 * a['arrived']:.1f} % | {100 * a['shield_share']:.1f} % |"
        )
    lines += [
        "",
        "Across seeds: mean of the seeds' means ± the t interval (95 %) over seeds.",
        "",
        f"| B (kHz) | seed | mean PSNR (dB) | {_header(margins)} (paired 95 % CIs) | arrival "
        "| shield share | arrival without shield |",
        "|---" * (6 + len(margins)) + "|",
    ]
    for row in r["rows"]:
        for i, s in enumerate(row["seeds"]):
            cells = [f"{s[f'minus {n}'][0]:+.2f} ± {s[f'minus {n}'][1]:.2f}" for n in margins]
            no = s.get("arrived_without_shield")
            lines.append(
                f"| {row['B'] / 1e3:g} | {i} | {s['mean_psnr']:.2f} ± {s['ci95']:.2f} | "
                + " | ".join(cells)
                + f" | {100 * s['arrived']:.1f} % | {100 * s['shield_share']:.1f} % | "
                + ("" if no is None else f"{100 * no:.1f} %")
                + " |"
            )
    lines += [
        "",
        "| B (kHz) | reference | setting (m/s) | mean PSNR (dB) | coverage | arrival |",
        "|---|---|---|---|---|---|",
    ]
    for row in r["rows"]:
        for name, s in row["references"].items():
            lines.append(reference_line(row["B"], name, s))
        if "expert" in row:
            lines.append(reference_line(row["B"], EXPERT, {"expert_k": row["expert"]["k"], **row["expert"]}))
    return "\n".join(lines)


def evaluate_run(
    folder: str | os.PathLike,
    episodes: int | None = None,
    validation_episodes: int | None = None,
    workers: int | None = None,
    log: Callable[[str], None] = print,
    extra: dict | None = None,
) -> dict:
    """:func:`compare` for the seeds of a finished ``train.py`` run folder in its own env (its
    ``RunConfig``; the counts default to the run's); writes its eval.json and eval.md (the folder
    claimed and locked meanwhile, ``semuav_jax.runfolder``)."""
    from semuav_jax.agents.runs import RUN_FILES, load_run
    from semuav_jax.runfolder import RunFolder

    load_run(folder)  # a one-line error before anything is written into the folder
    # of several processes, process 0 claims and writes; the others read (RunFolder.view)
    run_folder = RunFolder.claim(folder, "train.py run", adopt=RUN_FILES) if is_main() else RunFolder.view(folder)
    try:
        return _evaluate_run(run_folder, episodes, validation_episodes, workers, log, extra)
    finally:
        run_folder.release()


def _evaluate_run(
    run_folder: RunFolder,
    episodes: int | None,
    validation_episodes: int | None,
    workers: int | None,
    log: Callable[[str], None],
    extra: dict | None,
) -> dict:
    from semuav_jax.agents.runs import EVAL_FILE, EVAL_MD, load_run
    from semuav_jax.provenance import provenance

    folder = run_folder.path
    run, nets = load_run(folder)
    params, config = run.env_params(), run.agent
    network = q_network(params, config)
    bandwidths = bandwidths_of(config, params)
    pick = lambda given, saved: saved if given is None else given
    counts = pick(episodes, run.eval_episodes), pick(validation_episodes, run.validation_episodes)
    r = compare(network, nets, config, params, bandwidths, *counts, pick(workers, run.workers), log=log)
    r.update(agent_command=run.command, **_training_time(folder / EVAL_FILE), **(extra or {}), **provenance(params))
    if is_main():  # of several processes, process 0 writes
        run_folder.write(EVAL_FILE, json.dumps(r, indent=2).encode())
        run_folder.write(EVAL_MD, (markdown(r) + "\n").encode())
    return r


def _training_time(recorded: Path) -> dict:
    """``train_wall_s`` of the evaluation ``recorded`` (train.py's), kept when a run is evaluated again."""
    try:
        return {k: v for k, v in json.loads(recorded.read_text()).items() if k == "train_wall_s"}
    except (OSError, ValueError, AttributeError):
        return {}


def validation_table(
    folders: Iterable[str | os.PathLike],
    episodes: int = 500,
    bandwidths: Sequence[float] = BANDWIDTHS,
    references: bool = False,
    workers: int = 2,
) -> str:
    """Markdown: mean PSNR of every seed of each run folder on ``episodes`` layouts of
    ``keys.VALIDATION_SEED`` at each B, the numbers settings are chosen on (test layouts untouched);
    with ``references``, greedy-dwell and TSP-dwell at their knobs tuned on the same layouts. A run
    with demonstrations adds a row of its expert (one per distinct rule)."""
    from semuav_jax.agents.runs import load_run

    keys = episode_keys(VALIDATION_SEED, episodes)
    lines = [
        "| run | seed | " + " | ".join(f"{b / 1e3:g} kHz" for b in bandwidths) + " |",
        "|---|---|" + "---|" * len(bandwidths),
    ]
    params, experts = None, {}
    for folder in folders:
        run, nets = load_run(folder)
        params, config = run.env_params(), run.agent
        psnr = seed_metrics(q_network(params, config), nets, config, keys, params, bandwidths)["mean_psnr"].mean(-1)
        for s, row in enumerate(psnr):
            lines.append(f"| {folder} | {run.seed}:{s} | " + " | ".join(f"{x:.2f}" for x in row) + " |")
        if config.demo_steps:  # one row per expert: the rule an agent must beat
            rule = (config.demo_k, config.demo_edges, config.tour, config.option_margin, config.shield_margin)
            experts.setdefault((rule, repr(run.env), run.curves), (folder, config, params))
    for folder, config, at in experts.values():
        psnr = expert_metrics(config, keys, at, bandwidths)["mean_psnr"].mean(-1)
        lines.append(f"| {EXPERT} ({folder}) | | " + " | ".join(f"{x:.2f}" for x in psnr) + " |")
    if references and params is not None:
        tuned = tune(params, bandwidths, episodes, workers=workers, switch=False)
        for name in ("greedy-dwell", "tsp-dwell"):
            t = tuned[name]
            best = best_arriving(np.asarray(t["mean_psnr"]), np.asarray(t["arrived"]))
            row = [t["mean_psnr"][j][i] for j, i in enumerate(best)]
            lines.append(f"| {name} (tuned here) | | " + " | ".join(f"{x:.2f}" for x in row) + " |")
    return "\n".join(lines)
