"""Milliseconds per decision at the BS (docs/model.md eq. 7.15): one ``lookahead.choose`` (every
candidate simulated over the slots left to the end of the mission) for one UAV, as the BS computes
it within the processing delay (Delta_proc <= 0.1 s), for dwell-switch (12 candidates) and the agent
with search (the shipped agent, or the agent of ``--run``, with the search knobs of
``semuav-search``). States: the first slot of ``--states`` test layouts at B = 25 kHz, where the
most slots are left (K).

    taskset -c 0 python benchmarks/decision.py [--states 50] [--run FOLDER --every 16 --top 3 --no-rules]

Prints median and 99th percentile (ms) and writes ``benchmarks/decision.json``. Target: <= 100 ms
per decision on one core. Also the wall time of evaluating 100 layouts in one vmapped program.
"""

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from baselines.dwell_switch import dwell_switch_metrics, knob_table, switching
from baselines.evaluate import tsp_ranks
from semuav_jax.agents.runs import load_run
from semuav_jax.agents.search import SEARCH_EVERY, SEARCH_TARGETS, SEARCH_TOP, agent_switching, search_metrics
from semuav_jax.env import reset_state
from semuav_jax.io import atomic_write
from semuav_jax.keys import TEST_SEED, episode_keys
from semuav_jax.lookahead import check_switching, choose

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("--states", type=int, default=50)
ap.add_argument("--layouts", type=int, default=100, help="layouts of the batched evaluation")
ap.add_argument("--run", default=str(Path(__file__).resolve().parents[1] / "semuav_jax" / "data" / "agent"))
ap.add_argument("--every", type=int, default=SEARCH_EVERY, help="slots between two decisions of the agent")
ap.add_argument("--targets", type=int, default=SEARCH_TARGETS, help="option agents: candidate devices")
ap.add_argument("--top", type=int, default=SEARCH_TOP, help="option agents: simulate the M best options by Q")
ap.add_argument("--no-rules", action="store_true", help="option agents: no constant options or curve rules")
ap.add_argument("--out", default=str(Path(__file__).with_suffix(".json")))
args = ap.parse_args()

run, nets = load_run(args.run)
params = run.env_params().replace(B=25e3)
net = jax.tree.map(lambda x: jnp.asarray(x[0]), nets)
keys = episode_keys(TEST_SEED, max(args.states + 1, args.layouts))  # state 0 only compiles
rank = np.asarray(tsp_ranks(keys, params, workers=1))
# None: the agent's own (SEARCH_RULES, SEARCH_CURVES for option agents)
rules = curves = () if args.no_rules else None
knobs = (args.every, 1, args.targets, args.top, rules, curves)
searched = check_switching(agent_switching(run.agent, params, *knobs))
light = searched.light.count if searched.light else 0  # the rules among the candidates
cases = {
    "dwell-switch": (check_switching(switching()), knob_table(25.0, 0.0), lambda i: jnp.asarray(rank[i])),
    "agent with search": (
        searched,
        net,
        lambda i: jnp.zeros(()),
    ),
}
rows = []
for name, (sw, shared, per) in cases.items():
    decide = jax.jit(lambda s, pe, k, sw=sw, shared=shared: choose(sw, s, shared, pe, k, params, t=s.t)[0])
    times = []
    for i in range(args.states + 1):
        s = reset_state(jax.random.split(keys[i])[0], params)
        t0 = time.perf_counter()
        decide(s, per(i), jax.random.PRNGKey(i)).block_until_ready()
        times.append(time.perf_counter() - t0)
    ms = 1e3 * np.asarray(times[1:])  # the first includes compilation
    rows.append(
        {
            "policy": name,
            "candidates": sw.count if sw.shortlist is None else args.top + 1 + light,  # simulated per decision
            "median_ms": float(np.median(ms)),
            "p99_ms": float(np.percentile(ms, 99)),
        }
    )
for name, fn in (
    ("dwell-switch", lambda k: dwell_switch_metrics(k, params, 25.0, 0.0, rank[: len(k)])[0]),
    ("agent with search", lambda k: search_metrics(net, run.agent, k, params, *knobs)[0]),
):
    k = keys[: args.layouts]
    t0 = time.perf_counter()  # the first call includes compilation, the second does not
    jax.block_until_ready(fn(k))
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    jax.block_until_ready(fn(k))
    row = next(r for r in rows if r["policy"] == name)
    row |= {"layouts": args.layouts, "first_call_s": first, "episodes_s": time.perf_counter() - t0}

print(f"| policy | candidates | ms per decision, median | 99th percentile | {args.layouts} layouts (s) |")
print("|---|---|---|---|---|")
for r in rows:
    print(f"| {r['policy']} | {r['candidates']} | {r['median_ms']:.1f} | {r['p99_ms']:.1f} | {r['episodes_s']:.1f} |")
meta = {"run": args.run, "every": args.every, "targets": args.targets, "top": args.top, "rules": light}
atomic_write(args.out, json.dumps({"devices": jax.device_count(), **meta, "rows": rows}, indent=1).encode())
