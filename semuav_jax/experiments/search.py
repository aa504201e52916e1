"""The agent with search at the BS against the reactive agent, TSP-dwell, dwell-switch, the exact
planner and the certified bound (docs/ddqn.md, "The agent with search"): every training seed, with
and without search, on the same first ``episodes`` test layouts (``keys.TEST_SEED``; validation
layouts, ``keys.VALIDATION_SEED``, for choosing the search's knobs) as the references, the dwell
rules at the knobs the run's eval.json chose on validation layouts. Margins are per-episode paired
differences; across seeds, the mean of the seeds' means with its t interval. No seed is selected.

The command line: ``semuav-search RUN_FOLDER [--episodes 100] [--validation] [--json out.json]``
and the knobs of ``semuav_jax.cli.search``.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import jax
import numpy as np

from baselines import receding
from baselines.dwell import dwell_metrics, tsp_dwell
from baselines.evaluate import tsp_ranks
from baselines.report import BANDWIDTHS, certified_bound, switch_metrics
from semuav_jax.agents.evaluate import seed_metrics
from semuav_jax.agents.network import q_network
from semuav_jax.agents.runs import EVAL_FILE, load_run
from semuav_jax.agents.search import (
    SEARCH_BLOCK,
    SEARCH_EVERY,
    SEARCH_TARGETS,
    SEARCH_TOP,
    agent_switching,
    search_metrics,
)
from semuav_jax.experiments.references import lookup
from semuav_jax.experiments.stages import packable
from semuav_jax.keys import TEST_SEED, VALIDATION_SEED, episode_keys
from semuav_jax.lookahead import check_switching
from semuav_jax.params import EnvParams
from semuav_jax.sharding import map_episodes
from semuav_jax.stats import mean_ci, pm

VERSUS = ("agent", "tsp-dwell", "dwell-switch", "exact planner")
BOUND_GAPS = ("bound gap", "agent bound gap")


def compare_search(
    folder: str | os.PathLike,
    episodes: int = 100,
    bandwidths: Sequence[float] = BANDWIDTHS,
    every: int = SEARCH_EVERY,
    targets: int = SEARCH_TARGETS,
    top: int | None = SEARCH_TOP,
    rules: bool = True,
    validation: bool = False,
    tuning: str | os.PathLike | None = None,
    references: bool = True,
    log: Callable[[str], None] = print,
) -> dict:
    """Every number of the table (JSON-ready); the dwell knobs come from ``folder``'s eval.json, or
    from the eval.json ``tuning`` of another run of the same env. ``targets``, ``top``: the candidate
    devices of an option agent's search and how many of their options it simulates; ``rules``: whether
    it may also switch to the constant options of ``SEARCH_RULES`` and the curve rules of ``SEARCH_CURVES``
    (``agents/search.py``). ``references`` False: the agent with search against the agent alone, no
    reference flights and no bound (for choosing the knobs on validation layouts)."""
    if episodes < 2:
        raise ValueError(f"episodes must be >= 2 (an interval needs two), got {episodes}")
    run, nets = load_run(folder)
    source = Path(folder) / EVAL_FILE if tuning is None else Path(tuning)
    try:
        saved = json.loads(source.read_text())
        tuned = saved["tuning"]
        knobs = {
            float(row["B"]): (tuned["tsp-dwell"]["knobs"][j], tuned["dwell-switch"]["switch"][j])
            for j, row in enumerate(saved["rows"])
        }
    except (OSError, KeyError, ValueError, TypeError) as e:
        raise ValueError(
            f"{source} has no dwell tuning ({type(e).__name__}: {e}); run semuav-compare on it first"
        ) from None
    missing = [b for b in bandwidths if float(b) not in knobs]
    if missing:
        raise ValueError(f"{source} has no dwell tuning at B = {missing}")
    params = run.env_params()
    constant = curve = None if rules else ()  # None: the agent's own (SEARCH_RULES, SEARCH_CURVES for option agents)
    sw = check_switching(agent_switching(run.agent, params, every, 1, targets, top, constant, curve))
    network = q_network(params, run.agent)
    seed = VALIDATION_SEED if validation else TEST_SEED
    keys = episode_keys(seed, episodes)
    versus, gaps = (VERSUS, BOUND_GAPS) if references else (VERSUS[:1], ())
    rank = np.asarray(tsp_ranks(keys, params, workers=run.workers)) if references else None
    seeds = jax.tree.leaves(nets)[0].shape[0]
    agent = seed_metrics(network, nets, run.agent, keys, params, bandwidths)
    flown = None if validation or not references else _cached_flights(params, saved, episodes)
    rows = []
    for j, b in enumerate(bandwidths):
        pb = params.replace(B=float(b))
        (v_c, k_star, margin), (sv, sm) = knobs[float(b)]
        if not references:
            refs = {}
        elif flown is not None and float(b) in flown:
            refs = flown[float(b)]
        else:
            refs = {
                "tsp-dwell": jax.tree.map(np.asarray, dwell_metrics(tsp_dwell, keys, pb, v_c, k_star, margin, rank)),
                "dwell-switch": switch_metrics(keys, pb, sv, sm, rank),
                "exact planner": receding.fly(keys, pb, workers=run.workers)[0],
            }
        row = {"B": float(b), "seeds": [], "references": {k: mean_ci(m["mean_psnr"]) for k, m in refs.items()}}
        if references:
            bound = certified_bound(keys, pb)
            row["references"]["bound"] = mean_ci(bound)
        for s in range(seeds):
            net = jax.tree.map(lambda x, s=s: x[s], nets)
            t0 = time.perf_counter()
            m = map_episodes(
                lambda k, net=net, pb=pb: search_metrics(
                    net, run.agent, k, pb, every, 1, targets, top, constant, curve
                )[0],
                keys,
                block=SEARCH_BLOCK,
            )
            own = {k: v[s, j] for k, v in agent.items()}
            base = {"agent": own["mean_psnr"], **{k: r["mean_psnr"] for k, r in refs.items()}}
            res = {
                "mean_psnr": mean_ci(m["mean_psnr"]),
                "agent": mean_ci(own["mean_psnr"]),
                "arrived": float(np.mean(m["arrived"])),
                "wall_s": time.perf_counter() - t0,
                **{f"minus {n}": mean_ci(m["mean_psnr"] - base[n]) for n in versus},
            }
            if references:
                res["bound gap"] = mean_ci(bound - m["mean_psnr"])
                res["agent bound gap"] = mean_ci(bound - own["mean_psnr"])
            row["seeds"].append(res)
            log(
                f"B = {b / 1e3:g} kHz, seed {s}: search {res['mean_psnr'][0]:.2f} dB, agent {res['agent'][0]:.2f}, "
                + ", ".join(f"− {n} {res['minus ' + n][0]:+.2f}" for n in versus)
                + f" ({res['wall_s']:.0f} s)"
            )
        row["search"] = (
            {k: mean_ci([x[k][0] for x in row["seeds"]]) for k in ("mean_psnr", "agent")}
            | {f"minus {n}": mean_ci([x[f"minus {n}"][0] for x in row["seeds"]]) for n in versus}
            | {g: mean_ci([x[g][0] for x in row["seeds"]]) for g in gaps}
        )
        rows.append(row)
    return {
        "episodes": episodes,
        "layout_seed": seed,
        "layouts": "validation" if validation else "test",
        "every": every,
        "targets": targets if run.agent.uses_options else None,
        "top": top if run.agent.uses_options else None,
        "rules": sw.light.count if sw.light else 0,
        "seeds": seeds,
        "versus": list(versus),
        "rows": rows,
    }


def _cached_flights(params: EnvParams, saved: dict, episodes: int) -> dict[float, dict] | None:
    """{B: the references of :data:`VERSUS` on the first ``episodes`` test layouts} from the cached
    references (``experiments.references``) of the evaluation ``saved`` (an eval.json), when it holds
    them at the same knobs; else None."""
    counts = saved.get("episodes"), saved.get("validation_episodes")
    if not all(isinstance(c, int) for c in counts) or episodes > counts[0]:
        return None
    found = lookup(params, [row["B"] for row in saved["rows"]], *counts)
    as_json = lambda x: json.dumps(packable(x), sort_keys=True, default=lambda a: np.asarray(a).tolist())
    if found is None or as_json(found["tuning"]) != as_json(saved["tuning"]):
        return None
    names = VERSUS[1:]
    return {
        float(row["B"]): {n: {"mean_psnr": np.asarray(f[n]["mean_psnr"])[:episodes]} for n in names}
        for row, f in zip(saved["rows"], found["flights"])
    }


def markdown(r: dict) -> str:
    versus = r.get("versus", VERSUS)
    bound = all(g in row["search"] for row in r["rows"] for g in BOUND_GAPS)
    head = " | ".join(f"search − {n}" for n in versus) + (" | bound − search | bound − agent" if bound else "")
    gaps = (*(f"minus {n}" for n in versus), *(BOUND_GAPS if bound else ()))
    cells = lambda s: [f"{s[c][0]:+.2f} {pm(s[c][1])}" for c in gaps]
    knobs = f"a decision every {r['every']} slots" + (f", {r['targets']} target devices" if r["targets"] else "")
    knobs += f", the agent's {r['top']} best options by Q" if r.get("top") else ""
    knobs += f", {r['rules']} rules (constant options and curve rules)" if r.get("rules") else ""
    lines = [
        f"First {r['episodes']} {r['layouts']} layouts (seed {r['layout_seed']}); {knobs}; {r['seeds']} seeds, "
        "each paired per layout; across seeds: mean of the seeds' means ± t interval.",
        "",
        f"| B (kHz) | seed | agent with search (dB) | agent (dB) | {head} | s |",
        "|---" * (5 + len(gaps)) + "|",
    ]
    for row in r["rows"]:
        for i, s in enumerate(row["seeds"]):
            lines.append(
                f"| {row['B'] / 1e3:g} | {i} | {s['mean_psnr'][0]:.2f} | {s['agent'][0]:.2f} | "
                + " | ".join(cells(s))
                + f" | {s['wall_s']:.0f} |"
            )
        a = row["search"]
        lines.append(
            f"| {row['B'] / 1e3:g} | mean | {a['mean_psnr'][0]:.2f} {pm(a['mean_psnr'][1])} | "
            f"{a['agent'][0]:.2f} | " + " | ".join(cells(a)) + " | |"
        )
    return "\n".join(lines)
